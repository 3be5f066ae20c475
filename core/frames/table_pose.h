#pragma once
// A commanded turntable pose: the table angles that give C_p^q = R1(phi) R2(gamma) R3(psi).

#include "core/frames/rotations.h"

namespace turncal {

struct TablePose {
  double phi_rad = 0.0;    // inner axis, about x of q
  double gamma_rad = 0.0;  // middle axis, about y
  double psi_rad = 0.0;    // outer axis, about z

  Mat3<double> C_p_q() const { return turncal::C_p_q(phi_rad, gamma_rad, psi_rad); }
};

// The pose whose inner frame sees "down" (the third axis of p) along the unit vector down_q,
// turned by psi about the table's outer axis. Useful to design poses by where gravity points.
TablePose PoseWithDownAlong(const Eigen::Vector3d& down_q, double psi_rad);

}  // namespace turncal
