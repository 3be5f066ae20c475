#include "core/modeling/mag22_gauge.h"

#include <Eigen/Dense>
#include <cmath>

namespace turncal {

Eigen::MatrixXd Mag22GaugeTangentBasis(const MeasurementModel& model,
                                       const Eigen::VectorXd& theta) {
  // Constraints h1 = det(K_) - 1 and h2 = dB . R3(beta) B_NED; the tangent space is the null
  // space of their 2 x 22 Jacobian.
  const int kK = model.index_of("k11"), kBeta = model.index_of("beta"), kDB = model.index_of("dBx");
  const double* k = theta.data() + kK;
  Mat3<double> K;
  K << k[0], k[1], k[2], k[1], k[3], k[4], k[2], k[4], k[5];
  const Mat3<double> cof = K.determinant() * K.inverse().transpose();
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(2, theta.size());
  H(0, kK + 0) = cof(0, 0);
  H(0, kK + 1) = cof(0, 1) + cof(1, 0);
  H(0, kK + 2) = cof(0, 2) + cof(2, 0);
  H(0, kK + 3) = cof(1, 1);
  H(0, kK + 4) = cof(1, 2) + cof(2, 1);
  H(0, kK + 5) = cof(2, 2);
  const double beta = theta[kBeta];
  const Eigen::Vector3d B = model.excitation_ned();
  const Eigen::Vector3d u = R3(beta) * B;
  Mat3<double> dR3;
  dR3 << -std::sin(beta), std::cos(beta), 0, -std::cos(beta), -std::sin(beta), 0, 0, 0, 0;
  H.block<1, 3>(1, kDB) = u.transpose();
  H(1, kBeta) = theta.segment<3>(kDB).dot(dR3 * B);
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(H, Eigen::ComputeFullV);
  return svd.matrixV().rightCols(theta.size() - 2);
}

Eigen::MatrixXd Mag22NullDirections(const MeasurementModel& model, const Eigen::VectorXd& theta) {
  const int kG = model.index_of("g11"), kK = model.index_of("k11"), kBeta = model.index_of("beta"),
            kDB = model.index_of("dBx");
  const double* g = theta.data() + kG;
  const double* k = theta.data() + kK;
  Mat3<double> G;
  G << g[0], g[1], g[2], g[3], g[4], g[5], g[6], g[7], g[8];
  Mat3<double> K;
  K << k[0], k[1], k[2], k[1], k[3], k[4], k[2], k[4], k[5];
  auto set_K = [&](const Mat3<double>& m, int col, Eigen::MatrixXd* d) {
    const double entries[6] = {m(0, 0), m(0, 1), m(0, 2), m(1, 1), m(1, 2), m(2, 2)};
    for (int i = 0; i < 6; ++i) (*d)(kK + i, col) = entries[i];
  };
  Eigen::MatrixXd d = Eigen::MatrixXd::Zero(theta.size(), 2);
  set_K(K, 0, &d);
  d.block<3, 1>(kDB, 0) = -theta.segment<3>(kDB);
  const Mat3<double> GK = G * K;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) d(kG + 3 * r + c, 1) = GK(r, c);
  set_K(-K * K, 1, &d);
  d.block<3, 1>(kDB, 1) = -(R3(theta[kBeta]) * model.excitation_ned());
  return d;
}

void ApplyMag22Gauge(const MeasurementModel& model, Eigen::VectorXd* theta) {
  // Move along the two exact symmetries of seed eq. 21 (MODELS.md), which leave every prediction
  // unchanged, to the representative with dB . u = 0 (u = R3(beta) B_NED) and det(K_) = 1.
  const int kG = model.index_of("g11"), kK = model.index_of("k11"), kBeta = model.index_of("beta"),
            kDB = model.index_of("dBx");
  double* g = theta->data() + kG;
  double* k = theta->data() + kK;
  Mat3<double> G;
  G << g[0], g[1], g[2], g[3], g[4], g[5], g[6], g[7], g[8];
  Mat3<double> K;
  K << k[0], k[1], k[2], k[1], k[3], k[4], k[2], k[4], k[5];
  Eigen::Vector3d dB = theta->segment<3>(kDB);
  const Eigen::Vector3d u = R3((*theta)[kBeta]) * model.excitation_ned();
  // Symmetry 2: G' = G (I + t K_), K_' = (I + t K_)^-1 K_, dB' = dB - t u.
  const double t = dB.dot(u) / u.squaredNorm();
  const Mat3<double> A = Mat3<double>::Identity() + t * K;
  G = G * A;
  K = A.inverse() * K;
  K = 0.5 * (K + K.transpose());
  dB -= t * u;
  // Symmetry 1: K_' = lambda K_, dB' = dB / lambda with lambda = det(K_)^(-1/3).
  const double lambda = 1.0 / std::cbrt(K.determinant());
  K *= lambda;
  dB /= lambda;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) g[3 * r + c] = G(r, c);
  k[0] = K(0, 0), k[1] = K(0, 1), k[2] = K(0, 2), k[3] = K(1, 1), k[4] = K(1, 2), k[5] = K(2, 2);
  theta->segment<3>(kDB) = dB;
}

}  // namespace turncal
