#include "core/estimation/gyro_linear_start.h"

#include <Eigen/SVD>
#include <cmath>

namespace turncal {

namespace {

// Least squares A X = Y with columns scaled to unit norm; false when the scaled A has rank below
// its column count.
bool ScaledSolve(const Eigen::MatrixXd& A, const Eigen::MatrixXd& Y, Eigen::MatrixXd* X) {
  if (A.rows() < A.cols()) return false;
  Eigen::VectorXd scale = A.colwise().norm().transpose();
  for (Eigen::Index j = 0; j < scale.size(); ++j) scale[j] = scale[j] > 0 ? 1.0 / scale[j] : 1.0;
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(A * scale.asDiagonal(),
                                        Eigen::ComputeThinU | Eigen::ComputeThinV);
  svd.setThreshold(1e-8);
  if (svd.rank() < A.cols()) return false;
  *X = scale.asDiagonal() * svd.solve(Y);
  return true;
}

}  // namespace

bool SolveGyroLinearStart(const std::vector<Eigen::Vector3d>& omega_q,
                          const std::vector<Eigen::Vector3d>& f_q,
                          const std::vector<Eigen::Vector3d>& measured, bool with_g_sensitivity,
                          const Mat3<double>& nominal_G, GyroLinearStart* out, std::string* error) {
  const auto n = static_cast<Eigen::Index>(measured.size());
  if (omega_q.size() != measured.size() || f_q.size() != measured.size()) {
    if (error) *error = "the gyro linear start needs one rate and one force per record";
    return false;
  }
  Eigen::MatrixXd Y(n, 3);
  for (Eigen::Index i = 0; i < n; ++i) Y.row(i) = measured[i].transpose();
  const Eigen::Index nf = with_g_sensitivity ? 3 : 0;
  // The rates excite G only when they are well above the Earth's rate (7.3e-5 rad/s), which a
  // static pose's noise hides: 1 deg/s and more, in three independent directions.
  double largest = 0.0;
  for (const auto& w : omega_q) largest = std::max(largest, w.norm());
  if (largest > 1e-2) {
    Eigen::MatrixXd A(n, 3 + nf + 1);
    for (Eigen::Index i = 0; i < n; ++i) {
      A.row(i).head<3>() = omega_q[i].transpose();
      if (nf) A.row(i).segment<3>(3) = f_q[i].transpose();
      A(i, 3 + nf) = 1.0;
    }
    Eigen::MatrixXd X;
    if (ScaledSolve(A, Y, &X)) {
      out->G = X.topRows(3).transpose();
      if (nf) out->B = X.middleRows(3, 3).transpose();
      out->b = X.row(3 + nf).transpose();
      out->G_estimated = true;
      return true;
    }
  }
  // G held at nominal: y - G omega = B f + b.
  Eigen::MatrixXd A(n, nf + 1);
  Eigen::MatrixXd Yr(n, 3);
  for (Eigen::Index i = 0; i < n; ++i) {
    if (nf) A.row(i).head<3>() = f_q[i].transpose();
    A(i, nf) = 1.0;
    Yr.row(i) = (measured[i] - nominal_G * omega_q[i]).transpose();
  }
  Eigen::MatrixXd X;
  if (!ScaledSolve(A, Yr, &X)) {
    if (error) {
      *error =
          with_g_sensitivity
              ? "the records' specific forces do not span three directions (need g-sensitivity)"
              : "no records";
    }
    return false;
  }
  out->G = nominal_G;
  out->G_estimated = false;
  if (nf) out->B = X.topRows(3).transpose();
  out->b = X.row(nf).transpose();
  return true;
}

}  // namespace turncal
