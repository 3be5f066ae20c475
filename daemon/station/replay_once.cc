#include "daemon/station/replay_once.h"

#include <fmt/format.h>

#include <filesystem>

#include "daemon/state/atomic_file.h"
#include "drivers/capture/raw_stream.h"
#include "drivers/capture/tcap.h"

namespace turncal::daemon {

bool ReplayOnce(const std::string& path, const StationOptions& options,
                const std::string& result_out,
                const std::function<void(const nlohmann::json&)>& on_event,
                ReplayOnceOutcome* outcome, std::string* error) {
  if (!options.IsValid(error)) return false;
  drivers::CaptureReader reader;
  if (!reader.Open(path, error)) return false;
  std::vector<std::string> names;
  for (const auto& d : reader.header().devices) names.push_back(d.name);
  *outcome = ReplayOnceOutcome{};
  Station station(names, options, [&](const nlohmann::json& j) {
    ++outcome->events;
    if (on_event) on_event(j);
  });
  ReplayStats stats;
  // Free mode takes no poses: a capture's pose events are counted and left out.
  const bool free = options.pose_source == PoseSource::kFree;
  if (!ReplayInto(&reader, &station, !free, {}, &stats, error)) return false;
  outcome->result = station.Result();
  outcome->result["source"] = path;
  outcome->result["pose_commands"] = stats.pose_commands;
  outcome->result["pose_source"] = ToString(options.pose_source);
  if (free) outcome->result["pose_commands_ignored"] = stats.pose_commands;
  outcome->result["warnings"] = stats.warnings;
  for (std::size_t i = 0; i < names.size() && i < stats.decoders.size(); ++i) {
    const auto& c = stats.decoders[i];
    outcome->result["devices"][names[i]]["decoder"] = {{"frames", c.frames},
                                                       {"samples", c.samples},
                                                       {"bad_checksums", c.bad_checksums},
                                                       {"bytes_skipped", c.bytes_skipped},
                                                       {"lost_samples", c.lost_samples}};
  }
  if (!result_out.empty() &&
      !WriteFileAtomically(result_out, outcome->result.dump(2) + "\n", error)) {
    return false;
  }
  return true;
}

bool ReplayRawOnce(const std::string& path, drivers::Protocol protocol, double rate_hz,
                   const StationOptions& options, const std::string& result_out,
                   const std::function<void(const nlohmann::json&)>& on_event,
                   ReplayOnceOutcome* outcome, std::string* error) {
  if (!options.IsValid(error)) return false;
  std::vector<Sample> samples;
  drivers::RawStreamStats stats;
  if (!drivers::ReadRawStream(path, protocol, rate_hz, &samples, &stats, error)) {
    if (error->find("carry no time") != std::string::npos) *error += ": --rate HZ";
    return false;
  }
  stats.held_repeats = drivers::DropHeldRepeats(&samples);
  std::string name = std::filesystem::path(path).stem().string();
  if (name.empty()) name = "imu";
  *outcome = ReplayOnceOutcome{};
  Station station({name}, options, [&](const nlohmann::json& j) {
    ++outcome->events;
    if (on_event) on_event(j);
  });
  for (Sample& s : samples) {
    s.device = name;
    station.OnTick(s.t_host_ns);
    station.OnSample(0, s);
  }
  station.OnFinish(samples.empty() ? 0 : samples.back().t_host_ns);
  outcome->result = station.Result();
  outcome->result["source"] = path;
  outcome->result["pose_source"] = ToString(options.pose_source);
  const auto& c = stats.decoder;
  outcome->result["devices"][name]["decoder"] = {{"frames", c.frames},
                                                 {"samples", c.samples},
                                                 {"bad_checksums", c.bad_checksums},
                                                 {"bytes_skipped", c.bytes_skipped},
                                                 {"lost_samples", c.lost_samples}};
  outcome->result["raw"] = {
      {"protocol", drivers::ToString(protocol)},
      {"samples", samples.size()},
      {"held_repeats_dropped", stats.held_repeats},
      {"times", stats.device_clock ? "device clock" : fmt::format("{} Hz given", rate_hz)}};
  if (!result_out.empty() &&
      !WriteFileAtomically(result_out, outcome->result.dump(2) + "\n", error)) {
    return false;
  }
  return true;
}

}  // namespace turncal::daemon
