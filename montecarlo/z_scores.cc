#include "montecarlo/z_scores.h"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace turncal::montecarlo {

ZScoreSummary::ZScoreSummary(int parameters)
    : sum_(Eigen::VectorXd::Zero(parameters)),
      sum_sq_(Eigen::VectorXd::Zero(parameters)),
      beyond_3_(Eigen::VectorXi::Zero(parameters)),
      beyond_4_(Eigen::VectorXi::Zero(parameters)) {}

void ZScoreSummary::Add(const Eigen::VectorXd& z) {
  assert(z.size() == sum_.size());
  ++runs_;
  sum_ += z;
  sum_sq_ += z.cwiseAbs2();
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

bool ZScoreSummary::Honest(int parameter) const {
  const double mean = Mean()[parameter], std_z = Std()[parameter];
  return std_z >= 0.9 && std_z <= 1.1 && std::abs(mean) <= 0.15;
}

}  // namespace turncal::montecarlo
