#pragma once
// `turncal noise`'s inputs, read as a stream (issue 39 item 1): a capture, a raw device stream
// or text columns, each triad's samples going straight into its streaming Allan and Hadamard
// sums (core/analysis/streaming_allan.h), so that a 10-hour recording takes the memory of a
// minute's. A progress line on standard error for long inputs.

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/analysis/streaming_allan.h"

namespace turncal::tools {

struct NoiseInputArgs {
  std::string file;
  std::string protocol;                  // raw streams
  std::vector<std::string> text_triads;  // text columns: acc | gyr | mag, in column order
  double text_scale = 1.0;
  std::string device;
  double from_s = 0.0;
  double to_s = INFINITY;
  // Progress on standard error: "auto" (when it is a terminal), "always", "never".
  std::string progress = "auto";
};

// One triad's samples in [from, to] of its first sample: the sums, the sample period and gaps.
class TriadStream {
 public:
  explicit TriadStream(const char* name) : name_(name), allan_(3) {}
  void Add(double t_s, const Eigen::Vector3d& v, double from_s, double to_s);

  const char* name() const { return name_; }
  const StreamingAllan& allan() const { return allan_; }
  std::int64_t samples() const { return allan_.samples(); }
  // The median of the first intervals (4096 of them): the sample period.
  double period_s() const;
  // Intervals longer than 1.5 periods (lost samples; the estimator runs on as if none were).
  std::int64_t gaps() const;
  double span_s() const { return samples() > 1 ? t_last_ - t_kept_ : 0.0; }

 private:
  const char* name_;
  StreamingAllan allan_;
  bool started_ = false;
  double t_first_ = 0.0, t_kept_ = 0.0, t_last_ = 0.0;
  std::vector<double> first_intervals_;
  mutable double period_s_ = 0.0;  // once the first intervals are in
  std::int64_t late_gaps_ = 0;     // among the intervals after them
};

struct NoiseInput {
  TriadStream acc{"acc"}, gyr{"gyr"}, mag{"mag"};
  std::string source;  // a capture's device
  int skipped = 0;     // text lines that did not parse
  std::uint64_t bytes = 0;
  double seconds = 0.0;  // reading and summing, wall clock
};

// 0, or the exit code (messages on standard error).
int ReadNoiseInput(const NoiseInputArgs& args, NoiseInput* out);

}  // namespace turncal::tools
