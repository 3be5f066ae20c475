#pragma once
// The matrices and vectors models build from their parameter blocks (templated on the scalar, so
// Ceres differentiates through them), written once for the pose models (core/models/mag_common.h),
// the free models (core/models/free_common.h) and the simulator's truth (sim/tumble.cc).

#include "core/frames/rotations.h"

namespace turncal::params {

// imu_tk's triad correction, x = T K (raw - b), over kx ky kz m_yz m_zy m_zx: K = diag(k),
// T = [1 -m_yz m_zy; 0 1 -m_zx; 0 0 1] (upper triangular, small angles: the triad fixes its own
// frame, z its axis and y in its y-z plane).
template <typename T>
Mat3<T> UpperTK(const T* p) {
  Mat3<T> m;
  m << p[0], -p[3] * p[1], p[4] * p[2], T(0), p[1], -p[5] * p[2], T(0), T(0), p[2];
  return m;
}

// gyro9's full misalignment, T = [1 -m_yz m_zy; m_xz 1 -m_zx; -m_xy m_yx 1] (imu_tk's), times K:
// parameters kx ky kz m_yz m_zy m_zx m_xz m_xy m_yx.
template <typename T>
Mat3<T> FullTK(const T* p) {
  Mat3<T> m;
  m << p[0], -p[3] * p[1], p[4] * p[2], p[6] * p[0], p[1], -p[5] * p[2], -p[7] * p[0], p[8] * p[1],
      p[2];
  return m;
}

// A symmetric matrix from its six upper entries s11 s12 s13 s22 s23 s33.
template <typename T>
Mat3<T> Symmetric(const T* s) {
  Mat3<T> m;
  m << s[0], s[1], s[2], s[1], s[3], s[4], s[2], s[4], s[5];
  return m;
}

// A matrix from its nine entries, row by row.
template <typename T>
Mat3<T> MatrixRowMajor(const T* g) {
  Mat3<T> m;
  m << g[0], g[1], g[2], g[3], g[4], g[5], g[6], g[7], g[8];
  return m;
}

template <typename T>
Vec3<T> Vector(const T* v) {
  return Vec3<T>(v[0], v[1], v[2]);
}

}  // namespace turncal::params
