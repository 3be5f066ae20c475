#pragma once
// A raw device stream (a `.bin` of the bytes a device sent, no header, DESIGN.md "Capture file")
// as timed samples: decoded with the protocol named, each sample's host time from the device's
// own clock (relative to its first sample) or, for a device that sends none (a MIP stream of the
// magnetometer alone), from the sample rate given. Used by `turncald --replay FILE.bin --once`
// and `turncal free`.

#include <cstdint>
#include <string>
#include <vector>

#include "core/sequencing/sample.h"
#include "drivers/decoder.h"
#include "drivers/device_spec.h"

namespace turncal::drivers {

struct RawStreamStats {
  DecoderCounters decoder;
  // Magnetometer values the device repeated (sample and hold) and that were dropped
  // (DropHeldRepeats).
  std::int64_t held_repeats = 0;
  bool device_clock = false;  // the times came from the device's clock
};

// Decodes `path` with `protocol`. `rate_hz` (> 0) times samples that carry no device time; with
// neither, false with a message saying so. False with a message when the file cannot be read.
bool ReadRawStream(const std::string& path, Protocol protocol, double rate_hz,
                   std::vector<Sample>* out, RawStreamStats* stats, std::string* error);

// A device that sends a triad faster than it samples it repeats the last value (sample and hold:
// the MIP SDK fixture's magnetometer, ~20 Hz in a 50 Hz stream): those repeats are not new
// measurements, and their correlation breaks the stillness tests' white noise. In a stream of the
// magnetometer alone, samples repeating the previous value exactly are dropped when they are more
// than a third of the stream. Returns how many were dropped.
std::int64_t DropHeldRepeats(std::vector<Sample>* samples);

}  // namespace turncal::drivers
