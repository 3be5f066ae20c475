#pragma once
// The accelerometer's G matrix and its physical parameters (MODELS.md "G and the physical
// parameters"): G = (I+S) T_r^s C(eps) M. (I+S) T_r^s is lower triangular with a positive
// diagonal and C(eps) M is a rotation, so G = L Q is an LQ decomposition and the nine entries of
// G map one to one onto S, alpha and eps.

#include <string>

#include "core/frames/rotations.h"

namespace turncal {

struct AccelPhysical {
  Eigen::Vector3d S = Eigen::Vector3d::Zero();          // scale-factor errors Sx Sy Sz
  Eigen::Vector3d alpha{0.0, 0.0, 1.5707963267948966};  // alpha1 alpha2 alpha3, rad
  Eigen::Vector3d eps = Eigen::Vector3d::Zero();        // eps_x eps_y eps_z, rad
};

// (I+S) T_r^s(alpha): the sensor matrix of the case frame r, lower triangular.
template <typename T>
Mat3<T> AccelSensorMatrix(const T* S, const T* alpha) {
  Mat3<T> scale = Mat3<T>::Zero();
  for (int i = 0; i < 3; ++i) scale(i, i) = T(1) + S[i];
  return scale * T_r_s(alpha[0], alpha[1], alpha[2]);
}

// G = (I+S) T_r^s C(eps) M.
Mat3<double> AccelGFromPhysical(const AccelPhysical& p, const Mat3<double>& mounting);

// The inverse map by LQ decomposition. False with a message when G is singular, not finite, or
// has a negative determinant (no proper rotation: the nominal mounting M is wrong). The positive
// diagonal of L puts alpha3 in (0, pi).
bool AccelPhysicalFromG(const Mat3<double>& G, const Mat3<double>& mounting, AccelPhysical* out,
                        std::string* error);

// The LQ decomposition G = L Q with diag(L) > 0 and Q orthogonal (det Q = sign det G).
void DecomposeLQ(const Mat3<double>& G, Mat3<double>* L, Mat3<double>* Q);

}  // namespace turncal
