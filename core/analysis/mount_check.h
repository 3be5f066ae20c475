#pragma once
// Is the unit in its slot as configured? (issue 38). At rest an accelerometer measures the
// specific force -g, whatever its scale factors and bias do to it by a per cent: its direction in
// the case frame is where gravity is. The configured mount M predicts that direction at every
// pose, u = M C_p^q f_NED / |f| (the table's heading offset turns about the vertical and does not
// move it); the unit's mean gives the measured one, m. A unit in its slot has m = C(eps) u to its
// mounting error (a degree or less); a unit put in rotated 90 deg, 180 deg or upside down does not.
//
// From the poses so far, the rotation D (configured case -> observed case) that best turns the
// predicted directions into the measured ones (Wahba's problem: Kabsch's SVD), once they span two
// directions; snapped to the nearest of the 24 axis-aligned rotations when it is within
// snap_deg of one (a slot's units go in at 90-degree steps). The unit is wrong when D turns more
// than wrong_deg. With one direction only (the first pose, or every pose about one axis) D is not
// known yet, but a direction more than wrong_deg off already says the slot is wrong.
//
// What the check is not: the mounting error eps (the calibration's, the fixture's), nor a
// check of a magnetometer-only unit (the field's direction depends on the heading offset).
// Pure computation.

#include <string>
#include <vector>

#include "core/frames/rotations.h"

namespace turncal {

struct MountObservation {
  Eigen::Vector3d predicted_case;  // the specific force's direction the mount predicts
  Eigen::Vector3d measured;        // the accelerometer's mean (any scale)
};

struct MountCheckOptions {
  double wrong_deg = 30.0;  // a rotation beyond this is a wrong slot (a mounting error is ~1 deg)
  double snap_deg = 10.0;   // D within this of an axis-aligned rotation is that rotation
  // Two directions: the second eigenvalue of the predicted directions' mean outer product at
  // least this (two poses 37 deg apart and more).
  double min_spread = 0.1;
  double min_measured = 1e-6;  // a mean smaller than this (no gravity in it) is not used
};

struct MountCheck {
  int poses = 0;            // observations used
  bool determined = false;  // two directions: D is known
  bool wrong = false;       // the unit does not sit as configured
  // D: configured case -> observed case (identity until determined); the observed mount is
  // D M.
  Mat3<double> rotation = Mat3<double>::Identity();
  bool snapped = false;          // D is an axis-aligned rotation (snapped)
  double angle_deg = 0.0;        // D's angle
  double misfit_deg = 0.0;       // RMS angle between the measured directions and D's prediction
  double largest_off_deg = 0.0;  // the largest angle between a predicted and measured direction
};

MountCheck CheckMount(const std::vector<MountObservation>& observations,
                      const MountCheckOptions& options = {});

// The predicted direction of the specific force in the case frame at a table pose:
// M C_p^q f_NED (f_NED = -g_ned), normalised.
Eigen::Vector3d PredictedGravityDirection(const Mat3<double>& mount, const Mat3<double>& C_p_q,
                                          const Eigen::Vector3d& g_ned);

}  // namespace turncal
