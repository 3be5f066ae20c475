#pragma once
// How long the table takes between two poses: each axis moves with a trapezoidal rate profile
// (accelerate at most accel_dps2 to at most rate_dps, cruise, decelerate), the axes together in a
// coordinated move that ends when the slowest axis arrives, then the table settles for settle_s.
// Axes that turn without a stop (slip rings: the inner and outer axes of a three-axis flight
// motion simulator) take the shorter way round; the middle axis moves through its range.
//
// The planner weighs a pose's information against these seconds (core/planning/pose_planner.h), and
// the session simulator moves at the same rates when asked to (sim/session_sim.h).

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/estimation/bias_drift.h"
#include "core/frames/table_pose.h"

namespace turncal {

struct TableMotion {
  // Per axis in the order inner (phi), middle (gamma), outer (psi).
  Eigen::Vector3d rate_dps{20.0, 20.0, 20.0};    // the largest rate a move uses
  Eigen::Vector3d accel_dps2{20.0, 20.0, 20.0};  // the largest angular acceleration
  Eigen::Vector3i continuous{1, 0, 1};           // 1: turns without a stop
  double settle_s = 1.0;                         // after the move, before a dwell may start

  bool IsValid(std::string* error) const;

  // The angle each axis turns through from `from` to `to`, signed, radians (the shorter way for
  // continuous axes; ties at half a turn go the positive way).
  Eigen::Vector3d Travel(const TablePose& from, const TablePose& to) const;
  // Seconds of the coordinated move (0 for no change); settling not included.
  double MoveSeconds(const TablePose& from, const TablePose& to) const;
  // Seconds of one axis's trapezoidal profile over `angle_rad` (either sign).
  double AxisSeconds(int axis, double angle_rad) const;
  // The dwell windows of `poses` visited in order from `from` at time 0: each after its move and
  // settling, `dwell_s` long, the next move starting at its end.
  std::vector<TimeWindow> DwellWindows(const std::vector<TablePose>& poses, double dwell_s,
                                       const TablePose& from = {}) const;
};

}  // namespace turncal
