#pragma once
// A move between two static poses as the gyro saw it (issue 21, the third source): the raw gyro
// integrated over short blocks from a time the table rested at `from` to a time it rested at `to`.
// A gyroscope model integrated over the blocks must turn the table frame from the one pose to
// the other (the Earth turning meanwhile): core/estimation/move_residual.h.

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "core/frames/table_pose.h"

namespace turncal {

struct MoveRecord {
  TablePose from, to;  // static poses at both ends
  // Per block: the raw gyro integrated over it (rad), its seconds, and the raw accelerometer's
  // mean over it (m/s^2; empty when the device has none: a g-sensitivity then sees none).
  std::vector<Eigen::Vector3d> increment_rad;
  std::vector<double> block_s;
  std::vector<Eigen::Vector3d> force_mps2;
  double t_start_s = 0.0;  // the sensor's clock (drift), first and last sample
  double t_end_s = 0.0;
  std::int64_t samples = 0;
  std::int64_t bridged = 0;  // samples lost or left out inside it, bridged by the trapezoid

  double duration_s() const;
  // False with a message when the blocks disagree in number, a value is not finite, a block's
  // seconds are not positive, or the poses are rate segments.
  bool IsValid(std::string* error) const;
};

}  // namespace turncal
