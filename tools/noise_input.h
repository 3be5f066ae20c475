#pragma once
// `turncal noise`'s inputs, read as a stream (issue 39 item 1): a capture, a raw device stream
// or text columns, each triad's samples going straight into its streaming Allan and Hadamard
// sums (core/analysis/streaming_allan.h), so that a 10-hour recording takes the memory of a
// minute's. A progress line on standard error for long inputs.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/analysis/rest_noise.h"

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

struct NoiseInput {
  RestNoise noise;
  std::string source;  // a capture's device
  int skipped = 0;     // text lines that did not parse
  std::uint64_t bytes = 0;
  double seconds = 0.0;  // reading and summing, wall clock
};

// 0, or the exit code (messages on standard error).
int ReadNoiseInput(const NoiseInputArgs& args, NoiseInput* out);

}  // namespace turncal::tools
