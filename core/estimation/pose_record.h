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
  // The distinct values among the count samples when the triad held its values (a magnetometer
  // slower than the stream sends each value once per sample until the next: 50 Hz in a 100-Hz
  // stream twice): the mean's white noise averages over values, not samples, and covariance is
  // then the values' own. 0: each sample is its own value.
  std::int64_t values = 0;
};

// How many independent values a triad's mean averages: its values when it held them, else its
// samples.
inline std::int64_t IndependentCount(const TriadStats& s) {
  return s.values > 0 ? s.values : s.count;
}

// The covariance of a triad's mean from its own samples: the producer's mean_covariance, or the
// sample covariance / the independent count (unbiased, with that count - 1 degrees of freedom).
inline Eigen::Matrix3d SampleMeanCovariance(const TriadStats& s) {
  if (s.mean_covariance) return *s.mean_covariance;
  const double count = static_cast<double>(std::max<std::int64_t>(1, IndependentCount(s)));
  return s.covariance / count;
}

// The degrees of freedom of SampleMeanCovariance (0: not a sample covariance, nothing to correct).
inline double SampleMeanDof(const TriadStats& s) {
  return s.mean_covariance
             ? 0.0
             : static_cast<double>(std::max<std::int64_t>(1, IndependentCount(s)) - 1);
}

// A pose weighed by the inverse of a covariance estimated from its own samples is weighed too
// much on average: E[(W_hat + D)^-1] exceeds (W + D)^-1 (Jensen). To second order, with W_hat =
// S / n (S Wishart, nu degrees of freedom) inside a covariance C whose pose block of C^-1 is P,
//   E[C_hat^-1] = C^-1 + C^-1 (W P W + tr(P W) W) / nu C^-1,
// so weighing with W_hat + (W_hat P W_hat + tr(P W_hat) W_hat) / (nu - 4) makes the information
// (and chi^2) unbiased. Where the pose's error is all its white noise (P = W^-1) the added term is
// 4 W / (nu - 4): W_hat nu / (nu - 4), the inverse Wishart's exact mean for 3-vectors; where
// the pose-to-pose wander dominates (P W -> 0) it vanishes. Both ends were measured through the
// pipeline: an industrial accelerometer's long sessions (white noise 0.21 mm/s^2 per 4-s mean
// against 0.15 mm/s^2 of wander between poses) weighed by S / n gave chi^2 1 % large (the
// p-values' mean normal score +0.175 over 200 runs of 216 poses; +0.007 with the term), and a
// consumer magnetometer (0.025 mG of white noise per mean against 0.08 mG of wander) weighed by
// S nu / ((nu - 4) n) gave chi^2 ~1 % small (-0.15; 1.4 % at 20 Hz in memory, 4000 runs). Zero
// for nu <= 4 (the inverse's mean does not exist; the calibrator's white floor bounds it).
inline Eigen::Matrix3d SampleWeightCorrection(const Eigen::Matrix3d& w_hat,
                                              const Eigen::Matrix3d& precision_block, double nu) {
  if (!(nu > 4.0)) return Eigen::Matrix3d::Zero();
  const Eigen::Matrix3d pw = precision_block * w_hat;
  Eigen::Matrix3d add = (w_hat * pw + pw.trace() * w_hat) / (nu - 4.0);
  return 0.5 * (add + add.transpose());
}

// The covariance of a triad's mean as an estimator weighs it alone (its pose's error all white
// noise): SampleMeanCovariance scaled by nu / (nu - 4) (SampleWeightCorrection with P = W^-1).
// The free calibrator uses it; the turntable calibrator corrects each pose for its share of
// white noise (SampleWeightCorrection).
inline Eigen::Matrix3d WeighedMeanCovariance(const TriadStats& s) {
  const Eigen::Matrix3d w = SampleMeanCovariance(s);
  const double nu = SampleMeanDof(s);
  return nu > 4.0 ? Eigen::Matrix3d(w * (nu / (nu - 4.0))) : w;
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
  // A sample in motion rather than a still window (free mode's magnetometer in motion, issue
  // 37; core/estimation/free_motion.h): one value, its covariance the sample's noise.
  bool in_motion = false;
  // Such a sample's field magnitude relative to a still one's: a magnetometer's first-order
  // low-pass of a known bandwidth attenuates a field turning at w by 1 / sqrt(1 + (w / w_c)^2)
  // (MotionOptions::mag_bandwidth_hz); 1 for a still window or an unknown bandwidth.
  double mag_attenuation = 1.0;

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
