#pragma once
// A commanded turntable pose: the table angles that give C_p^q = R1(phi) R2(gamma) R3(psi).

#include <string>

#include "core/frames/rotations.h"

namespace turncal {

// A table axis: the outer (psi, about z of p), middle (gamma) or inner (phi, about x of q).
enum class TableAxis { kNone, kOuter, kMiddle, kInner };
const char* ToString(TableAxis axis);  // "none", "outer", "middle", "inner"
// By name ("outer", "middle", "inner"); false when unknown.
bool TableAxisFromString(const std::string& name, TableAxis* axis);

struct TablePose {
  double phi_rad = 0.0;    // inner axis, about x of q
  double gamma_rad = 0.0;  // middle axis, about y
  double psi_rad = 0.0;    // outer axis, about z
  // A rate segment (issue 21): the table turns about `rate_axis` at a constant `rate_radps`
  // (positive: the axis's angle grows) while the other two axes hold the angles above; the
  // rotating axis's own angle is then not meaningful. kNone: a static pose.
  TableAxis rate_axis = TableAxis::kNone;
  double rate_radps = 0.0;

  bool is_rate() const { return rate_axis != TableAxis::kNone; }
  Mat3<double> C_p_q() const { return turncal::C_p_q(phi_rad, gamma_rad, psi_rad); }
  // C_p^q averaged over whole revolutions of the rotating axis (a rate segment; the pose's own
  // C_p^q otherwise): a vector fixed in p averages to its component along the rotation axis.
  Mat3<double> MeanC_p_q() const;
  // The angular rate of q relative to p, in q, rad/s: zero for a static pose; constant over a rate
  // segment because the axes outside the rotating one hold still.
  Eigen::Vector3d TableRate_q() const;
};

// The pose whose inner frame sees "down" (the third axis of p) along the unit vector down_q,
// turned by psi about the table's outer axis. Useful to design poses by where gravity points.
TablePose PoseWithDownAlong(const Eigen::Vector3d& down_q, double psi_rad);

}  // namespace turncal
