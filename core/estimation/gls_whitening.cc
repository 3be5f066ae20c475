#include "core/estimation/gls_whitening.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>

namespace turncal {

bool BuildGlsWhitening(const std::vector<TimeWindow>& windows,
                       const std::vector<Eigen::Matrix3d>& white, const BiasDrift& drift,
                       GlsWhitening* out, std::string* error) {
  const int n = static_cast<int>(windows.size());
  out->order = TimeOrder(windows);
  std::vector<TimeWindow> sorted;
  for (int i : out->order) sorted.push_back(windows[static_cast<std::size_t>(i)]);
  Eigen::MatrixXd& C = out->C;
  C = Eigen::MatrixXd::Zero(3 * n, 3 * n);
  for (int k = 0; k < n; ++k) {
    C.block<3, 3>(3 * k, 3 * k) = white[static_cast<std::size_t>(out->order[k])];
  }
  if (n > 0 && drift.enabled()) {
    for (int axis = 0; axis < 3; ++axis) {
      const Eigen::MatrixXd D = DriftIncrementCovariance(drift, axis, sorted, n - 1);
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) C(3 * i + axis, 3 * j + axis) += D(i, j);
    }
  }
  Eigen::LLT<Eigen::MatrixXd> llt(C);
  if (llt.info() != Eigen::Success) {
    if (error) *error = "the poses' joint error covariance is not positive definite";
    return false;
  }
  out->W = llt.matrixL().solve(Eigen::MatrixXd::Identity(3 * n, 3 * n));
  if (!out->W.allFinite()) {
    if (error) *error = fmt::format("the poses' joint error covariance is singular");
    return false;
  }
  return true;
}

RawResidualCache::RawResidualCache(std::vector<const ceres::CostFunction*> raw, int num_parameters)
    : raw_(std::move(raw)),
      n_params_(num_parameters),
      r_(raw_.size()),
      J_(raw_.size(), RowJacobian::Zero(3, num_parameters)) {}

bool RawResidualCache::Evaluate(const double* theta, bool with_jacobians) {
  const auto N = static_cast<std::size_t>(n_params_);
  if (valid_ && (jacobians_ || !with_jacobians) && theta_.size() == N &&
      std::equal(theta_.begin(), theta_.end(), theta)) {
    return true;
  }
  valid_ = false;
  theta_.assign(theta, theta + N);
  const double* parameters[1] = {theta_.data()};
  for (std::size_t i = 0; i < raw_.size(); ++i) {
    double* jacobians[1] = {J_[i].data()};
    if (!raw_[i]->Evaluate(parameters, r_[i].data(), with_jacobians ? jacobians : nullptr)) {
      return false;
    }
  }
  valid_ = true;
  jacobians_ = with_jacobians;
  return true;
}

InnovationCost::InnovationCost(std::shared_ptr<RawResidualCache> cache, int num_parameters)
    : cache_(std::move(cache)) {
  set_num_residuals(3);
  mutable_parameter_block_sizes()->push_back(num_parameters);
}

void InnovationCost::Add(int pose, const Eigen::Matrix3d& weight) {
  terms_.push_back({pose, weight});
}

bool InnovationCost::Evaluate(double const* const* parameters, double* residuals,
                              double** jacobians) const {
  using RowJacobian = RawResidualCache::RowJacobian;
  const int N = parameter_block_sizes()[0];
  const bool want_jacobian = jacobians != nullptr && jacobians[0] != nullptr;
  if (!cache_->Evaluate(parameters[0], want_jacobian)) return false;
  Eigen::Map<Eigen::Vector3d> out(residuals);
  out.setZero();
  for (const Term& t : terms_) out.noalias() += t.weight * cache_->residual(t.pose);
  if (want_jacobian) {
    Eigen::Map<RowJacobian> J(jacobians[0], 3, N);
    J.setZero();
    for (const Term& t : terms_) J.noalias() += t.weight * cache_->jacobian(t.pose);
  }
  return true;
}

}  // namespace turncal
