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
// - the per-sample noise: the measured profile's or the sensor class's; with neither (a stream
//   that never stood still, no --sensor-class) estimated from the scatter about an algebraic
//   ellipsoid through the points (robust: 1.4826 x the median absolute deviation), and said so --
//   the chi^2 is then no check of the noise;
// - many points (a long stream): every k-th new value, at most max_points, so that the solve and
//   its drift model stay fast; the rest are counted;
// - the time: each point's window is its sample's, on the device clock when the sample has one
//   (the sequencer's sensor clock for a stream whose device clock never resets), else the host's.
// Pure computation.

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/modeling/free_model.h"
#include "core/sequencing/free_intervals.h"
#include "core/sequencing/sample.h"

namespace turncal {

struct MotionOptions {
  int max_points = 1500;
  // The magnetometer's per-sample noise, 1 sigma per axis (device unit), and where it came from
  // ("measured", "the industrial class"); unset: from the points' own scatter.
  std::optional<Eigen::Vector3d> mag_sigma;
  std::string noise_source;
};

struct MotionPoints {
  std::vector<FreeInterval> points;  // in time order
  std::int64_t samples_with_mag = 0;
  std::int64_t held = 0;          // repeats of the previous value, dropped
  std::int64_t in_intervals = 0;  // new values inside (or next to) a still interval
  std::int64_t decimated = 0;     // new values in motion left out to keep max_points
  double period_s = 0.0;          // between new values (the magnetometer's own rate's period)
  Eigen::Vector3d sigma = Eigen::Vector3d::Zero();
  std::string noise_source;  // as given, or "the points' scatter about an ellipsoid"
  // One line for the report: what was taken and how.
  std::string Summary() const;
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
