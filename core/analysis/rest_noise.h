#pragma once
// A sensor at rest, its noise characterised as the samples arrive (issue 39 item 1): each
// triad's streaming Allan and Hadamard sums (streaming_allan.h), its sample period and gaps, and
// the analysis of every axis -- the deviations with their intervals (allan_edf.h) and the
// fitted noise model (allan.h). `turncal noise` runs it on files, turncald on a live device
// during a rest ({"cmd":"noise"}). Pure computation.

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "core/analysis/allan.h"
#include "core/analysis/allan_edf.h"
#include "core/analysis/ieee_noise.h"
#include "core/analysis/streaming_allan.h"
#include "core/analysis/warm_up.h"

namespace turncal {

// One triad's samples in [from, to] seconds of its first sample.
class RestTriad {
 public:
  explicit RestTriad(const char* name) : name_(name), allan_(3) {}
  void Add(double t_s, const Eigen::Vector3d& v, double from_s = 0.0, double to_s = INFINITY);

  const char* name() const { return name_; }
  const StreamingAllan& allan() const { return allan_; }
  // One-second means from the first sample (longer for recordings past 9 hours): the warm-up.
  const BinnedMeans& bins() const { return bins_; }
  std::int64_t samples() const { return allan_.samples(); }
  // The median of the first intervals (4096 of them): the sample period.
  double period_s() const;
  // Intervals longer than 1.5 periods (lost samples; the estimator runs on as if none were).
  std::int64_t gaps() const;
  double span_s() const { return samples() > 1 ? t_last_ - t_kept_ : 0.0; }

 private:
  const char* name_;
  StreamingAllan allan_;
  BinnedMeans bins_;
  bool started_ = false;
  double t_first_ = 0.0, t_kept_ = 0.0, t_last_ = 0.0;
  std::vector<double> first_intervals_;
  mutable double period_s_ = 0.0;  // once the first intervals are in
  std::int64_t late_gaps_ = 0;     // among the intervals after them
};

// The three triads of one device.
struct RestNoise {
  RestTriad acc{"acc"}, gyr{"gyr"}, mag{"mag"};
};

// One Allan point with its intervals, the Hadamard deviation beside it.
struct RestNoisePoint {
  std::int64_t m = 0, stride = 1;
  double tau_s = 0.0;
  int alpha = 0;  // the noise type its edf assumes (allan_edf.h)
  double adev = 0.0, edf = 0.0;
  VarianceInterval ci68, ci95;  // of the Allan deviation
  double hdev = NAN, hedf = 0.0;
  VarianceInterval hci68, hci95;
};

struct RestNoiseAxis {
  std::string triad;  // acc | gyr | mag
  int axis = 0;
  std::vector<AllanPoint> fitted;      // the points fitted (up to a ninth of the recording)
  std::vector<RestNoisePoint> points;  // every one, with intervals
  std::int64_t gaps = 0;
  NoiseFit fit;       // turncald's noise model (white, Gauss-Markov, random walk)
  IeeeNoiseFit ieee;  // IEEE 952's Q, N, B, K, R with their sigma
  // The transient from the first sample (switch-on, when the recording starts there), its
  // threshold the floor of the Allan deviation.
  WarmUpFit warm_up;
  std::size_t samples = 0;
  double rate_hz = 0.0;
};

// Every axis of every triad with at least 16 intervals.
std::vector<RestNoiseAxis> AnalyseRestNoise(const RestNoise& noise);

// The unit of a triad's values: m/s^2, rad/s, G.
const char* RestNoiseUnit(const std::string& triad);

}  // namespace turncal
