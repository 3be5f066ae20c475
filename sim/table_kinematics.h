#pragma once
// The table's kinematics the simulator's paths share (sim/session_simulator.cc's moves and spins,
// sim/hand_motion.cc's hand): the smooth step and the inner frame's rate from the angles' rates.

#include <Eigen/Core>
#include <cmath>

#include "core/frames/rotations.h"

namespace turncal::sim {

// Smooth step 0 -> 1 over [0, 1] with zero rate at both ends, (1 - cos(pi s)) / 2, and its integral
// from 0.
inline double SCurve(double s) { return 0.5 * (1.0 - std::cos(M_PI * s)); }
inline double SCurveIntegral(double s) { return s / 2 - std::sin(M_PI * s) / (2 * M_PI); }

// Angular rate of the table's inner frame q with respect to p, expressed in q, for the angles
// (phi, gamma, psi) and their rates: [w x] = -dC/dt C^T for C = C_p^q.
inline Eigen::Vector3d TableBodyRate(const Eigen::Vector3d& angles, const Eigen::Vector3d& rates) {
  const double h = 1e-5;
  const Eigen::Vector3d plus = angles + h * rates, minus = angles - h * rates;
  const Mat3<double> C = C_p_q(angles[0], angles[1], angles[2]);
  const Mat3<double> dC =
      (C_p_q(plus[0], plus[1], plus[2]) - C_p_q(minus[0], minus[1], minus[2])) / (2 * h);
  const Mat3<double> W = -dC * C.transpose();
  return Eigen::Vector3d(W(2, 1) - W(1, 2), W(0, 2) - W(2, 0), W(1, 0) - W(0, 1)) * 0.5;
}

}  // namespace turncal::sim
