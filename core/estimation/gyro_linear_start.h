#pragma once
// The gyroscope's linear start (issue 21): omega_m = G_w omega_q + B_g f_q + b_g is linear in
// G_w, B_g and b_g given each record's inertial rate omega_q and specific force f_q in the table's
// inner frame (MeasurementModel's stimulus: the Earth's rate and gravity, averaged over a rate
// segment's revolutions, plus the table's rate). Each output axis is one least-squares problem.

#include <string>
#include <vector>

#include "core/frames/rotations.h"

namespace turncal {

struct GyroLinearStart {
  Mat3<double> G = Mat3<double>::Identity();
  Mat3<double> B = Mat3<double>::Zero();  // zero when not estimated
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  bool G_estimated = false;  // false: G held at the nominal mounting (no rate excitation)
};

// omega_q, f_q and measured hold one entry per record. With `with_g_sensitivity` B_g is estimated
// too. When the rates do not span three dimensions well above the Earth's rate (static poses
// only), G is held at `nominal_G` and only b_g (and B_g) are solved. False with a message when
// even that is not determined (too few records, or f_q not diverse enough for B_g).
bool SolveGyroLinearStart(const std::vector<Eigen::Vector3d>& omega_q,
                          const std::vector<Eigen::Vector3d>& f_q,
                          const std::vector<Eigen::Vector3d>& measured, bool with_g_sensitivity,
                          const Mat3<double>& nominal_G, GyroLinearStart* out, std::string* error);

}  // namespace turncal
