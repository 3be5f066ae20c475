#pragma once
// Is the table turning at a steady rate? (issue 21: a rate segment's window). The gyroscope alone
// decides: the accelerometer sees gravity turn in the sensor frame and the lever arm's
// centripetal acceleration, so it is not still even when the rate is.
//
// Over a sliding window of W samples of the gyro triad, the rate is steady when, per axis,
//   spread   the sample variance is within the white noise's chi^2 quantile at z normal
//            deviates (Wilson-Hilferty) plus the table's rate ripple (relative `ripple` of the
//            rate, a sinusoid's variance);
//   halves   the two halves' means agree within z sigma of the white noise plus twice the ripple;
// and the rate's magnitude is the announced one within 5 % plus 2 deg/s (a scale error, the
// mounting and the bias cannot move it further; a table still spinning up or down can).
// Like the stillness detector it looks ahead: a sample counts only once it has left a steady
// window. Memory is the window, allocated once.

#include <cstdint>
#include <string>
#include <vector>

#include "core/sequencing/stillness.h"

namespace turncal {

struct RateSteadyOptions {
  double ripple = 1e-3;  // the table's rate ripple allowed, relative to the rate
  // Normal deviates of each test: 6.5 is a false alarm of ~4e-11 per window and test, so that
  // the thousands of windows of a session's rate segments pass when the rate is steady.
  double z = 6.5;
  bool IsValid(std::string* error) const;
};

class RateSteadiness {
 public:
  // `window` samples; `sigma` the gyro's per-sample white noise per axis (rad/s); the announced
  // rate in rad/s.
  RateSteadiness(std::int64_t window, const Eigen::Vector3d& sigma, double rate_radps,
                 const RateSteadyOptions& options);

  // Adds a sample (its gyro triad); true when the window is full and steady. The sample that left
  // the window, if any, goes to *evicted.
  bool Push(const StillSample& sample, StillSample* evicted, bool* has_evicted);
  // An isolated spike: a gyro axis further than 8 sigma of white noise plus twice the ripple from
  // the full window's mean (the sequencer holds such a sample until the next shows whether the
  // rate itself moved). False while the window fills.
  bool IsOutlier(const StillSample& sample) const;
  // Consecutive steady windows up to the last Push.
  std::int64_t steady_run() const { return run_; }
  // Why the last unsteady window was not steady ("" before the window is full).
  const std::string& finding() const { return finding_; }
  std::int64_t window() const { return window_; }

 private:
  bool Steady();
  std::int64_t window_;
  Eigen::Vector3d sigma_;
  double rate_radps_;
  RateSteadyOptions options_;
  std::vector<StillSample> ring_;
  std::size_t next_ = 0;
  std::int64_t count_ = 0, run_ = 0;
  Eigen::Vector3d sum_ = Eigen::Vector3d::Zero();  // of the window's gyro samples
  std::string finding_;
};

}  // namespace turncal
