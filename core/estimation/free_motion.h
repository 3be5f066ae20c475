#pragma once
// The magnetometer's samples in motion as data (issue 37): the field's magnitude is the same in
// every orientation whether the device is still or turning, so in free mode every new
// magnetometer value outside the still intervals is one norm equation, as the vendors' tools and
// ArduPilot's compass calibration take a hand's continuous rotation. Each becomes a one-sample
// FreeInterval (PoseRecord::in_motion; only `mag`, its covariance the per-sample noise) that the
// magnetometer models (magellipsoid, magsphere, accmag's norm) use like any interval, and that
// every other model ignores (no accelerometer, no gyro, no move).
//
// What motion brings, and what is done about it:
// - held repeats (a magnetometer slower than the stream: the device sends its last value again)
//   are not new measurements and are dropped;
// - the per-sample noise: pooled over the still intervals' samples when they hold a thousand or
//   more (the noise meter's one second would leave sigma 7 % uncertain, and the chi^2 of a
//   thousand points sees that), else the measured profile's or the sensor class's; with neither
//   (a stream that never stood still, no --sensor-class) estimated from the scatter about an
//   algebraic ellipsoid through the points (robust: 1.4826 x the median absolute deviation), and
//   said so -- the chi^2 is then no check of the noise;
// - many points (a long stream): every k-th new value, at most max_points, so that the solve and
//   its drift model stay fast; the rest are counted;
// - the time: each point's window is its sample's, on the device clock when the sample has one
//   (the sequencer's sensor clock for a stream whose device clock never resets), else the host's.
// Pure computation.

#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "core/modeling/free_model.h"
#include "core/sequencing/free_intervals.h"
#include "core/sequencing/host_clock.h"
#include "core/sequencing/sample.h"

namespace turncal {

// The median of `values` (the upper of the middle two for an even count; 0 for none).
double MedianOf(std::vector<double> values);

struct MotionOptions {
  int max_points = 1500;
  // The magnetometer's per-sample noise, 1 sigma per axis (device unit), and where it came from
  // ("measured", "the industrial class"); unset: from the points' own scatter.
  std::optional<Eigen::Vector3d> mag_sigma;
  std::string noise_source;
  // The degrees of freedom mag_sigma was estimated with (infinite: a datasheet's or a long
  // rest's) and the rate of the samples it was measured over: a magnetometer slower than that
  // stream repeated its values there, and each counts once (the dof scaled by its own rate over
  // that one).
  double mag_sigma_dof = std::numeric_limits<double>::infinity();
  double mag_sigma_rate_hz = 0.0;
  // The host times mag_sigma was measured over (a noise meter's second): the values there are
  // left out when mag_sigma is what the points are weighed with, so that the fit check's F test
  // compares the residuals with an independent estimate of their noise (the meter's values in
  // both made the check's p-values pile in the middle).
  std::optional<std::pair<double, double>> mag_sigma_measured_host_s;
  // The magnetometer's noise as `profile` has it (sigma, dof, rate, source, when measured); false
  // (nothing set) when the profile has no magnetometer.
  bool TakeNoise(const NoiseProfile& profile);
  // The still intervals' own samples, pooled, are the noise instead when they hold at least this
  // many (their scatter about their means: sigma to sqrt(1 / 2n)).
  double min_pooled_samples = 1000;
  // The magnetometer's bandwidth, Hz, when known (a device's filter setting or datasheet; 0: not
  // accounted for): a first-order low-pass lags a turning field and attenuates it by
  // 1 / sqrt(1 + (w / (2 pi bandwidth))^2), w the field's rate of turn in the sensor's frame,
  // measured from the values on either side of each (the hard iron taken out by an algebraic
  // ellipsoid through them). The norm does not see the lag; each point's expected magnitude is
  // attenuated (FreeInterval::mag_attenuation).
  double mag_bandwidth_hz = 0.0;
};

struct MotionPoints {
  std::vector<FreeInterval> points;  // in time order
  std::int64_t samples_with_mag = 0;
  std::int64_t held = 0;                  // repeats of the previous value, dropped
  std::int64_t in_intervals = 0;          // new values inside (or next to) a still interval
  std::int64_t in_noise_measurement = 0;  // new values the noise was measured from, left out
  std::int64_t decimated = 0;             // new values in motion left out to keep max_points
  double period_s = 0.0;  // between new values (the magnetometer's own rate's period)
  bool frozen = false;    // every sample with the field held one value
  Eigen::Vector3d sigma = Eigen::Vector3d::Zero();
  // Its degrees of freedom: a noise meter's second of a 50-Hz magnetometer has about 50, so that
  // sigma is uncertain by 10 % and the fit check is an F test against it (FreeCalibratorOptions::
  // motion_noise_dof); infinite for a datasheet's, a long rest's, or the points' own scatter
  // (which the chi^2 cannot check).
  double sigma_dof = std::numeric_limits<double>::infinity();
  std::string noise_source;  // as given, or "the points' scatter about an ellipsoid"
  // The bandwidth accounted for (MotionOptions::mag_bandwidth_hz), the field's fastest turn among
  // the points, rad/s, and the smallest attenuation.
  double bandwidth_hz = 0.0;
  double fastest_turn_radps = 0.0;
  double smallest_attenuation = 1.0;
  // One line for the report: what was taken and how.
  std::string Summary() const;
};

// One new magnetometer value (held repeats dropped), as turncald keeps and journals them.
struct MotionValue {
  double t_host_s = 0.0;             // when the device sent it, on the host's clock
  std::optional<double> t_device_s;  // its device (or the sequencer's sensor) clock
  Eigen::Vector3d mag = Eigen::Vector3d::Zero();
  std::optional<double> temp_c;
};

// The magnetometer's new values of a stream, sample by sample (turncald's free pose source keeps
// one per device). At most `max_values` are kept: beyond that every other one is dropped and from
// then on only every 2nd (4th, ...) new value taken, so that a long session's memory stays bounded
// (counted in thinned()).
class MotionCollector {
 public:
  explicit MotionCollector(std::size_t max_values = 30000) : max_values_(max_values) {}
  // A sample (every one of the stream, with the field or not: its host time is mapped to when
  // the device sent it, HostClock, as the still intervals' are): its field, when new, is kept
  // (`t_device_s` overrides the sample's device time: the station's sensor clock). True when a
  // value was kept.
  bool Push(const Sample& sample, std::optional<double> t_device_s);
  bool Push(const Sample& sample) { return Push(sample, sample.t_device_s); }
  // A value kept earlier (a resumed journal's).
  void Add(const MotionValue& value);
  const std::vector<MotionValue>& values() const { return values_; }
  std::int64_t samples_with_mag() const { return samples_with_mag_; }
  std::int64_t held() const { return held_; }
  std::int64_t thinned() const { return thinned_; }
  // The points outside the still `intervals` (MagnetometerInMotion's rules).
  MotionPoints Select(const std::vector<FreeInterval>& intervals,
                      const MotionOptions& options) const;

 private:
  void Keep(const MotionValue& value);
  std::size_t max_values_;
  HostClock clock_;
  std::vector<MotionValue> values_;
  std::optional<Eigen::Vector3d> previous_;
  std::int64_t samples_with_mag_ = 0, held_ = 0, thinned_ = 0;
  std::int64_t stride_ = 1, since_kept_ = 0;
};

// The points of `samples` (in time order) outside the still `intervals`.
MotionPoints MagnetometerInMotion(const std::vector<Sample>& samples,
                                  const std::vector<FreeInterval>& intervals,
                                  const MotionOptions& options);

// What `turncal free` fits, from a stream of samples: the still intervals the sequencer in free
// mode finds (SequencerOptions `options`, valid), then with `motion` (not null) the
// magnetometer's samples in motion after them, its noise the profile's the sequencer used (else
// the points' scatter).
struct FreeCollected {
  FreeIntervals found;
  std::optional<MotionPoints> motion;  // when looked for and the stream has a magnetometer
  std::vector<FreeInterval> data;      // found.intervals, then motion's points
};
FreeCollected CollectFree(const std::vector<Sample>& samples, const SequencerOptions& options,
                          const MotionOptions* motion);

}  // namespace turncal
