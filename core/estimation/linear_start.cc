#include "core/estimation/linear_start.h"

#include <Eigen/QR>
#include <Eigen/SVD>
#include <cmath>

namespace turncal {

Eigen::Matrix<double, 9, 1> LinearRegressor(const TablePose& pose, const Eigen::Vector3d& v) {
  const Mat3<double> C = pose.C_p_q();
  Eigen::Matrix<double, 9, 1> m;
  m.segment<3>(0) = v.x() * C.col(0) + v.y() * C.col(1);
  m.segment<3>(3) = v.y() * C.col(0) - v.x() * C.col(1);
  m.segment<3>(6) = v.z() * C.col(2);
  return m;
}

bool SolveLinearStart(const std::vector<TablePose>& poses,
                      const std::vector<Eigen::Vector3d>& measured, const Eigen::Vector3d& v_ned,
                      LinearStart* out, std::string* error) {
  const int n = static_cast<int>(poses.size());
  if (n < 10 || measured.size() != poses.size()) {
    if (error) *error = "the linear start needs at least 10 poses, have " + std::to_string(n);
    return false;
  }
  // Each output axis is an independent 10-unknown problem with the same regressor matrix.
  Eigen::MatrixXd A(n, 10);
  Eigen::MatrixXd Y(n, 3);
  for (int i = 0; i < n; ++i) {
    A.row(i).head<9>() = LinearRegressor(poses[i], v_ned).transpose();
    A(i, 9) = 1.0;
    Y.row(i) = measured[i].transpose();
  }
  // Scale columns to unit norm: the first two blocks are ~0.0167 for gravity, the rest ~10.
  Eigen::VectorXd scale = A.colwise().norm().transpose();
  for (int j = 0; j < 10; ++j) scale[j] = scale[j] > 0 ? 1.0 / scale[j] : 1.0;
  const Eigen::MatrixXd As = A * scale.asDiagonal();
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(As, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::VectorXd s = svd.singularValues();
  // Relative tolerance 1e-10: exact degeneracies (a pose set turning about one axis) give
  // ~1e-16; the weakest real direction (beta through 0.0167 m/s^2) stays far above.
  svd.setThreshold(1e-10);
  out->regressor_rank = static_cast<int>(svd.rank());
  out->regressor_min_singular = s[9] / s[0];
  if (out->regressor_rank < 10) {
    if (error) {
      *error = "the poses are not diverse enough for the linear start: regressor rank " +
               std::to_string(out->regressor_rank) + " of 10";
    }
    return false;
  }
  const Eigen::MatrixXd X = scale.asDiagonal() * svd.solve(Y);  // 10 x 3
  out->H_prime = X.topRows(9).transpose();
  out->b = X.row(9).transpose();
  out->G = out->H_prime.block<3, 3>(0, 6);
  const Mat3<double> cos_block = out->H_prime.block<3, 3>(0, 0);
  const Mat3<double> sin_block = out->H_prime.block<3, 3>(0, 3);
  // H' blocks are G cos(beta) and G sin(beta) when v is [vx, vy, vz] (seed eq. 9).
  out->beta = std::atan2((sin_block.array() * out->G.array()).sum(),
                         (cos_block.array() * out->G.array()).sum());
  return true;
}

}  // namespace turncal
