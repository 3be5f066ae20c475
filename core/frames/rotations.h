#pragma once
// Frames and rotations of MODELS.md ("Frames and rotations"), templated on the scalar type so
// Ceres can differentiate through them (T = double or ceres::Jet).
//
// All rotations are passive (frame) rotations: C_a_b maps a vector's coordinates in frame a to
// its coordinates in frame b. Angles are radians.

#include <Eigen/Dense>
#include <array>
#include <cmath>

namespace turncal {

template <typename T>
using Mat3 = Eigen::Matrix<T, 3, 3>;
template <typename T>
using Vec3 = Eigen::Matrix<T, 3, 1>;

// Elementary frame rotation about x: R1(a) = [1 0 0; 0 c s; 0 -s c].
template <typename T>
Mat3<T> R1(const T& a) {
  using std::cos;
  using std::sin;
  const T c = cos(a), s = sin(a), zero(0), one(1);
  Mat3<T> r;
  r << one, zero, zero, zero, c, s, zero, -s, c;
  return r;
}

// Elementary frame rotation about y: R2(a) = [c 0 -s; 0 1 0; s 0 c].
template <typename T>
Mat3<T> R2(const T& a) {
  using std::cos;
  using std::sin;
  const T c = cos(a), s = sin(a), zero(0), one(1);
  Mat3<T> r;
  r << c, zero, -s, zero, one, zero, s, zero, c;
  return r;
}

// Elementary frame rotation about z: R3(a) = [c s 0; -s c 0; 0 0 1].
template <typename T>
Mat3<T> R3(const T& a) {
  using std::cos;
  using std::sin;
  const T c = cos(a), s = sin(a), zero(0), one(1);
  Mat3<T> r;
  r << c, s, zero, -s, c, zero, zero, zero, one;
  return r;
}

// Turntable base p -> moving inner frame q: C_p^q = R1(phi) R2(gamma) R3(psi). Equals seed eq. 4
// entry by entry (tests/core/rotations_test.cc).
template <typename T>
Mat3<T> C_p_q(const T& phi, const T& gamma, const T& psi) {
  return R1(phi) * R2(gamma) * R3(psi);
}

// Local level NED -> turntable base p: C_NED^p = R3(beta), beta the table's heading offset
// (seed eq. 5).
template <typename T>
Mat3<T> C_ned_p(const T& beta) {
  return R3(beta);
}

// Small mounting error of the case: C(eps) = R1(eps_x) R2(eps_y) R3(eps_z) (project convention).
// The full table -> case rotation is C_q^r = C(eps) * M with M the nominal mounting
// (see C_q_r below).
template <typename T>
Mat3<T> C_eps(const T& eps_x, const T& eps_y, const T& eps_z) {
  return R1(eps_x) * R2(eps_y) * R3(eps_z);
}

// Table inner frame q -> sensor case r: C_q^r = C(eps) * M, M the nominal (axis-aligned) mounting.
template <typename T>
Mat3<T> C_q_r(const T& eps_x, const T& eps_y, const T& eps_z,
              const Mat3<double>& mounting = Mat3<double>::Identity()) {
  return C_eps(eps_x, eps_y, eps_z) * mounting.cast<T>();
}

// Case r -> non-orthogonal sensitive axes s: rows are the unit sensitive axes written in r
// (project convention). det = cos(a1) cos(a2) sin(a3); nominal a1 = a2 = 0, a3 = pi/2 gives I.
template <typename T>
Mat3<T> T_r_s(const T& alpha1, const T& alpha2, const T& alpha3) {
  using std::cos;
  using std::sin;
  const T zero(0), one(1);
  Mat3<T> t;
  t << one, zero, zero,                //
      cos(alpha3), sin(alpha3), zero,  //
      sin(alpha2), sin(alpha1) * cos(alpha2), cos(alpha1) * cos(alpha2);
  return t;
}

// The 24 proper rotations whose entries are 0 or +-1 (the axis-aligned mountings).
const std::array<Mat3<double>, 24>& AxisAlignedRotations();

// The axis-aligned rotation nearest to `c` in the Frobenius norm (largest trace of c^T R).
Mat3<double> NearestAxisAlignedRotation(const Mat3<double>& c);

}  // namespace turncal
