#pragma once
// PoseRecord: the unit the calibrator consumes (DESIGN.md "Data flow"): the commanded table
// angles and the statistics of each triad over one stationary window.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>

#include "core/estimation/move_record.h"
#include "core/frames/table_pose.h"

namespace ceres {
class CostFunction;
}

namespace turncal {

struct TriadStats {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  // Sample covariance of the individual samples.
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  // Covariance of the mean when the producer estimated it in a way that survives correlated
  // noise (batch means over sub-windows). Absent: covariance / count is used.
  std::optional<Eigen::Matrix3d> mean_covariance;
  std::int64_t count = 0;
};

// The covariance of a triad's mean as the estimators weigh it: the producer's mean_covariance, or
// the sample covariance / count scaled by nu / (nu - 4), nu = count - 1 degrees of freedom. A
// sample covariance S of 3-vectors has E[S^-1] = Sigma^-1 nu / (nu - 4) (the inverse Wishart's
// mean): weighed by S^-1 itself, a record's chi^2 comes out that much too large (+1 % at 400
// samples, +27 % at 20), which through the pipeline leaned the chi^2 p-values of an industrial
// accelerometer's long sessions to small values (mean z of the p-values 0.175 over 200 runs of
// 216 poses; 0.007 with the factor). The factor makes the information unbiased; the sigma it
// gives the parameters is that much (0.5 % at 400 samples) larger. With fewer than 6 samples the
// mean of S^-1 does not exist and the covariance is left as it is (the calibrator's white floor
// bounds it).
inline Eigen::Matrix3d WeighedMeanCovariance(const TriadStats& s) {
  if (s.mean_covariance) return *s.mean_covariance;
  const double count = static_cast<double>(std::max<std::int64_t>(1, s.count));
  const double nu = count - 1.0;
  const double unbiased = nu > 4.0 ? nu / (nu - 4.0) : 1.0;
  return s.covariance * (unbiased / count);
}

// How the sensor's reported temperature moved over a record's window (deg C).
struct TemperatureSpread {
  double std_c = 0.0;  // sample standard deviation about the mean
  double min_c = 0.0;
  double max_c = 0.0;
};

struct PoseRecord {
  TablePose pose;
  std::optional<TriadStats> acc;  // specific force, m/s^2
  std::optional<TriadStats> gyr;  // rad/s
  std::optional<TriadStats> mag;  // device unit
  double t_start_s = 0.0;         // window start and end, seconds on the host's clock
  double t_end_s = 0.0;
  // The same window on the sensor's own clock (the sequencer's: the device clock kept continuous
  // across resets), which bias drift evolves in; NaN when not known (then the host's is used).
  double sensor_t_start_s = std::numeric_limits<double>::quiet_NaN();
  double sensor_t_end_s = std::numeric_limits<double>::quiet_NaN();
  // The sensor's temperature over the window: its mean (deg C), and how much it moved (absent
  // when the device reports none).
  std::optional<double> temp_c;
  std::optional<TemperatureSpread> temp_spread;
  // The move from the previous captured static pose to this one as the gyro saw it (issue 21;
  // core/sequencing/move_tracker.h): absent for the first pose, a rate segment, or a move the
  // sequencer dropped.
  std::optional<MoveRecord> move_in;

  double duration_s() const { return t_end_s - t_start_s; }
  bool has_sensor_window() const {
    return std::isfinite(sensor_t_start_s) && std::isfinite(sensor_t_end_s) &&
           sensor_t_end_s > sensor_t_start_s;
  }
  // The window drift and averaging are timed in: the sensor's when known, else the host's.
  double sensor_start_s() const { return has_sensor_window() ? sensor_t_start_s : t_start_s; }
  double sensor_end_s() const { return has_sensor_window() ? sensor_t_end_s : t_end_s; }
};

// One pose as the estimator weighs it: the measured mean of the model's triad and
// Sigma^{-1/2}, Sigma the covariance of that mean (floored, with the pose-to-pose offset).
struct WeightedPose {
  TablePose pose;
  Eigen::Vector3d measured = Eigen::Vector3d::Zero();
  Eigen::Matrix3d sqrt_information = Eigen::Matrix3d::Identity();
  // A gyroscope's move between two poses (core/estimation/move_residual.h): its unwhitened
  // residual, whose Jacobian stands for the model's prediction's (`pose` is its destination).
  std::shared_ptr<const ceres::CostFunction> raw_residual;
};

}  // namespace turncal
