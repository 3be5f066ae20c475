#include "montecarlo/z_scores.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cassert>
#include <cmath>
#include <random>

namespace turncal::montecarlo {

ZScoreSummary::ZScoreSummary(int parameters)
    : sum_(Eigen::VectorXd::Zero(parameters)),
      sum_sq_(Eigen::VectorXd::Zero(parameters)),
      sum_outer_(Eigen::MatrixXd::Zero(parameters, parameters)),
      beyond_3_(Eigen::VectorXi::Zero(parameters)),
      beyond_4_(Eigen::VectorXi::Zero(parameters)) {}

void ZScoreSummary::Add(const Eigen::VectorXd& z) {
  assert(z.size() == sum_.size());
  ++runs_;
  sum_ += z;
  sum_sq_ += z.cwiseAbs2();
  sum_outer_.selfadjointView<Eigen::Lower>().rankUpdate(z);
  for (Eigen::Index i = 0; i < z.size(); ++i) {
    beyond_3_[i] += std::abs(z[i]) > 3;
    beyond_4_[i] += std::abs(z[i]) > 4;
  }
}

Eigen::VectorXd ZScoreSummary::Mean() const { return sum_ / runs_; }

Eigen::VectorXd ZScoreSummary::Std() const {
  const Eigen::VectorXd mean = Mean();
  Eigen::VectorXd std_z(mean.size());
  for (Eigen::Index i = 0; i < mean.size(); ++i) {
    std_z[i] = std::sqrt(std::max(0.0, sum_sq_[i] / runs_ - mean[i] * mean[i]));
  }
  return std_z;
}

namespace {

// The verdict on one parameter's mean and spread (ZScoreSummary::Honest).
bool HonestMeanAndSpread(double mean, double std_z) {
  return std_z >= 1 - kHonestStdZBound && std_z <= 1 + kHonestStdZBound &&
         std::abs(mean) <= kHonestMeanZBound;
}

}  // namespace

bool ZScoreSummary::Honest(int parameter) const {
  return HonestMeanAndSpread(Mean()[parameter], Std()[parameter]);
}

Eigen::MatrixXd ZScoreSummary::Correlation() const {
  const Eigen::Index k = sum_.size();
  Eigen::MatrixXd correlation = Eigen::MatrixXd::Identity(k, k);
  if (runs_ < 2) return correlation;
  const Eigen::VectorXd mean = Mean(), std_z = Std();
  for (Eigen::Index i = 0; i < k; ++i) {
    for (Eigen::Index j = 0; j < i; ++j) {
      if (!(std_z[i] > 0 && std_z[j] > 0)) continue;
      const double c = (sum_outer_(i, j) / runs_ - mean[i] * mean[j]) / (std_z[i] * std_z[j]);
      correlation(i, j) = correlation(j, i) = std::clamp(c, -1.0, 1.0);
    }
  }
  return correlation;
}

double HonestRowPassChance(const Eigen::MatrixXd& correlation, int runs, int rows) {
  const Eigen::Index k = correlation.rows();
  if (k == 0 || runs < 2 || rows < 1) return std::nan("");
  // A square root of the correlation that survives a singular one (two parameters whose z move
  // together): V sqrt(max(lambda, 0)).
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(correlation);
  const Eigen::MatrixXd root =
      eigen.eigenvectors() * eigen.eigenvalues().cwiseMax(0.0).cwiseSqrt().asDiagonal();
  std::mt19937_64 rng(20261130);
  std::normal_distribution<double> normal;
  Eigen::VectorXd e(k), z(k), sum(k), sum_sq(k);
  int passed = 0;
  for (int row = 0; row < rows; ++row) {
    sum.setZero();
    sum_sq.setZero();
    for (int run = 0; run < runs; ++run) {
      for (Eigen::Index i = 0; i < k; ++i) e[i] = normal(rng);
      z.noalias() = root * e;
      sum += z;
      sum_sq += z.cwiseAbs2();
    }
    bool all = true;
    for (Eigen::Index i = 0; i < k && all; ++i) {
      const double mean = sum[i] / runs;
      all = HonestMeanAndSpread(mean, std::sqrt(std::max(0.0, sum_sq[i] / runs - mean * mean)));
    }
    passed += all;
  }
  return static_cast<double>(passed) / rows;
}

}  // namespace turncal::montecarlo
