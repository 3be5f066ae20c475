#pragma once
// The rank and the inverse Fisher information of a whitened Jacobian J, from the SVD of J with
// its columns scaled to unit norm (a parameter's unit does not decide what counts as rank loss):
// the calibrator's and the calibration over temperature's (calibrator.cc, thermal_calibrator.cc).

#include <Eigen/Core>
#include <Eigen/SVD>

namespace turncal {

struct ScaledSvd {
  Eigen::VectorXd scale;  // 1 / the column norms (1 for a zero column)
  Eigen::JacobiSVD<Eigen::MatrixXd> svd;
  int rank = 0;  // singular values above rank_tolerance x the largest

  ScaledSvd(const Eigen::MatrixXd& J, double rank_tolerance) {
    scale = J.colwise().norm().transpose();
    for (Eigen::Index j = 0; j < scale.size(); ++j) scale[j] = scale[j] > 0 ? 1.0 / scale[j] : 1.0;
    // The full V: with fewer equations than parameters (a calibration over temperature early in
    // a session) the thin V lacks the null space's directions, which callers take from its
    // right columns.
    svd.compute(J * scale.asDiagonal(), Eigen::ComputeFullV);
    const Eigen::VectorXd& s = svd.singularValues();
    for (Eigen::Index i = 0; i < s.size(); ++i) rank += s[i] > rank_tolerance * s[0];
  }
  const Eigen::VectorXd& singular_values() const { return svd.singularValues(); }
  // (J^T J)^+ over the first `rank` singular directions, in the unscaled parameters.
  Eigen::MatrixXd PseudoInverseCovariance() const {
    const Eigen::VectorXd& s = svd.singularValues();
    Eigen::VectorXd inv(rank);
    for (int i = 0; i < rank; ++i) inv[i] = 1.0 / (s[i] * s[i]);
    const auto V = svd.matrixV().leftCols(rank);
    return scale.asDiagonal() * V * inv.asDiagonal() * V.transpose() * scale.asDiagonal();
  }
};

}  // namespace turncal
