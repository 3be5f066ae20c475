#include "core/gls_whitening.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <numeric>

namespace turncal {

bool BuildGlsWhitening(const std::vector<TimeWindow>& windows,
                       const std::vector<Eigen::Matrix3d>& white, const BiasDrift& drift,
                       GlsWhitening* out, std::string* error) {
  const int n = static_cast<int>(windows.size());
  out->order.resize(static_cast<std::size_t>(n));
  std::iota(out->order.begin(), out->order.end(), 0);
  std::stable_sort(out->order.begin(), out->order.end(), [&](int a, int b) {
    return windows[static_cast<std::size_t>(a)].t0_s < windows[static_cast<std::size_t>(b)].t0_s;
  });
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

InnovationCost::InnovationCost(int num_parameters) {
  set_num_residuals(3);
  mutable_parameter_block_sizes()->push_back(num_parameters);
}

void InnovationCost::Add(const ceres::CostFunction* raw, const Eigen::Matrix3d& weight) {
  terms_.push_back({raw, weight});
}

bool InnovationCost::Evaluate(double const* const* parameters, double* residuals,
                              double** jacobians) const {
  using RowJacobian = Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::RowMajor>;
  const int N = parameter_block_sizes()[0];
  const bool want_jacobian = jacobians != nullptr && jacobians[0] != nullptr;
  Eigen::Map<Eigen::Vector3d> out(residuals);
  out.setZero();
  RowJacobian J_sum, J;
  double* raw_jacobians[1] = {nullptr};
  if (want_jacobian) {
    J_sum = RowJacobian::Zero(3, N);
    J.resize(3, N);
    raw_jacobians[0] = J.data();
  }
  Eigen::Vector3d r;
  for (const Term& t : terms_) {
    if (!t.raw->Evaluate(parameters, r.data(), want_jacobian ? raw_jacobians : nullptr)) {
      return false;
    }
    out += t.weight * r;
    if (want_jacobian) J_sum += t.weight * J;
  }
  if (want_jacobian) Eigen::Map<RowJacobian>(jacobians[0], 3, N) = J_sum;
  return true;
}

}  // namespace turncal
