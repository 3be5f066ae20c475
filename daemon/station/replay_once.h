#pragma once
// `turncald --replay FILE --once [--result-out FILE]`: the whole station pipeline (decoders,
// sequencer, calibrators, observability, gate) on a capture at full speed, then the result
// (DESIGN.md "Command line"). The same Station the service loop drives.

#include <nlohmann/json.hpp>
#include <string>

#include "daemon/station/station.h"
#include "drivers/device_spec.h"

namespace turncal::daemon {

struct ReplayOnceOutcome {
  nlohmann::json result;  // Station::Result() plus the replay's counts and warnings
  std::uint64_t events = 0;
};

// Replays the capture at `path`; every station event goes to `on_event` (may be empty). False
// with *error when the capture cannot be read or the options cannot work. When `result_out` is
// not empty the result is written there atomically.
bool ReplayOnce(const std::string& path, const StationOptions& options,
                const std::string& result_out,
                const std::function<void(const nlohmann::json&)>& on_event,
                ReplayOnceOutcome* outcome, std::string* error);

// The same on a raw device stream (`turncald --replay FILE.bin --protocol P --once`, DESIGN.md
// "Capture file"): one device named after the file, its samples timed by the device's clock or,
// without one, `rate_hz` (drivers/capture/raw_stream.h); a magnetometer the device holds between
// updates keeps only its new values. The result adds "raw": the decoder's counters, the repeats
// dropped and where the times came from.
bool ReplayRawOnce(const std::string& path, drivers::Protocol protocol, double rate_hz,
                   const StationOptions& options, const std::string& result_out,
                   const std::function<void(const nlohmann::json&)>& on_event,
                   ReplayOnceOutcome* outcome, std::string* error);

}  // namespace turncal::daemon
