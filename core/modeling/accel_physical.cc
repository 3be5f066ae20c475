#include "core/modeling/accel_physical.h"

#include <Eigen/QR>
#include <algorithm>
#include <cmath>

namespace turncal {

Mat3<double> AccelGFromPhysical(const AccelPhysical& p, const Mat3<double>& mounting) {
  return AccelSensorMatrix(p.S.data(), p.alpha.data()) *
         C_q_r(p.eps.x(), p.eps.y(), p.eps.z(), mounting);
}

void DecomposeLQ(const Mat3<double>& G, Mat3<double>* L, Mat3<double>* Q) {
  // G^T = Q' R (Householder QR) => G = R^T Q'^T. Flip signs so that diag(L) > 0.
  Eigen::HouseholderQR<Mat3<double>> qr(G.transpose());
  Mat3<double> R = qr.matrixQR().triangularView<Eigen::Upper>();
  Mat3<double> Qp = qr.householderQ();
  for (int i = 0; i < 3; ++i) {
    if (R(i, i) < 0) {
      R.row(i) *= -1.0;
      Qp.col(i) *= -1.0;
    }
  }
  *L = R.transpose();
  *Q = Qp.transpose();
}

bool AccelPhysicalFromG(const Mat3<double>& G, const Mat3<double>& mounting, AccelPhysical* out,
                        std::string* error) {
  auto fail = [&](const std::string& message) {
    if (error) *error = message;
    return false;
  };
  if (!G.allFinite()) return fail("G is not finite");
  const double det = G.determinant();
  if (!(std::abs(det) > 1e-12 * std::pow(G.norm(), 3))) return fail("G is singular");
  if (det < 0) {
    return fail("det G < 0: no rotation relates the sensor to the table with this mounting");
  }
  Mat3<double> L, Q;
  DecomposeLQ(G, &L, &Q);

  AccelPhysical p;
  // Row 1 of (I+S)T is (1+Sx)[1 0 0]; row 2 (1+Sy)[cos a3, sin a3, 0];
  // row 3 (1+Sz)[sin a2, sin a1 cos a2, cos a1 cos a2].
  p.S.x() = L(0, 0) - 1.0;
  const double norm2 = L.row(1).norm();
  p.S.y() = norm2 - 1.0;
  p.alpha.z() = std::atan2(L(1, 1), L(1, 0));
  const double norm3 = L.row(2).norm();
  p.S.z() = norm3 - 1.0;
  p.alpha.y() = std::asin(std::clamp(L(2, 0) / norm3, -1.0, 1.0));
  p.alpha.x() = std::atan2(L(2, 1), L(2, 2));

  // C(eps) = Q M^T = R1(ex) R2(ey) R3(ez): [.. .. -sin ey; .. .. cos ey sin ex; .. .. cos ey cos
  // ex].
  const Mat3<double> C = Q * mounting.transpose();
  p.eps.y() = -std::asin(std::clamp(C(0, 2), -1.0, 1.0));
  p.eps.z() = std::atan2(C(0, 1), C(0, 0));
  p.eps.x() = std::atan2(C(1, 2), C(2, 2));
  *out = p;
  return true;
}

}  // namespace turncal
