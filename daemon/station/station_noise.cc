// A rest's noise on a live device (Station::RestNoiseRequest; docs/NOISE.md): the samples go
// into the same streaming Allan and Hadamard sums as `turncal noise` (core/analysis/rest_noise.h),
// a few sums per sample, memory flat however long the rest.
#include <fmt/format.h>

#include <filesystem>

#include "core/analysis/rest_noise.h"
#include "daemon/state/atomic_file.h"
#include "daemon/state/state_dir.h"
#include "daemon/station/station.h"
#include "protocol/messages.h"
#include "protocol/noise_json.h"

namespace turncal::daemon {

struct Station::RestNoiseRun {
  RestNoise noise;
  std::string started;  // UTC stamp
  int poses_announced = 0;
};

void Station::AddRestNoise(int device, const Sample& s) {
  RestNoiseRun& run = *rest_noise_[static_cast<std::size_t>(device)];
  const double t = s.t_device_s ? *s.t_device_s : static_cast<double>(s.t_host_ns) * 1e-9;
  if (s.acc_mps2) run.noise.acc.Add(t, *s.acc_mps2);
  if (s.gyr_radps) run.noise.gyr.Add(t, *s.gyr_radps);
  if (s.mag) run.noise.mag.Add(t, *s.mag);
}

void Station::NoteRestNoiseMove(std::size_t device) { ++rest_noise_[device]->poses_announced; }

nlohmann::json Station::RestNoiseRequest(const std::string& device, const std::string& action) {
  std::size_t index = devices_.size();
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    if (devices_[i]->name == device) index = i;
  }
  if (index == devices_.size()) {
    std::string names;
    for (const auto& d : devices_) names += (names.empty() ? "" : ", ") + d->name;
    return protocol::ErrorMessage(
        fmt::format("noise: no device '{}' (devices: {})", device, names));
  }
  rest_noise_.resize(devices_.size());
  std::shared_ptr<RestNoiseRun>& run = rest_noise_[index];
  nlohmann::json reply = {{"class", "NOISE"}, {"device", device}};
  if (action == "start") {
    reply["restarted"] = run != nullptr;
    run = std::make_shared<RestNoiseRun>();
    run->started = UtcStamp();
    reply["state"] = "measuring";
    reply["started"] = run->started;
    return reply;
  }
  if (!run) {
    return protocol::ErrorMessage(fmt::format(
        "noise: nothing is measured on {}: start with {{\"cmd\":\"noise\",\"device\":\"{}\","
        "\"action\":\"start\"}} while it rests",
        device, device));
  }
  const std::vector<RestNoiseAxis> axes = AnalyseRestNoise(run->noise);
  double seconds = 0.0;
  std::int64_t samples = 0;
  for (const RestTriad* t : {&run->noise.acc, &run->noise.gyr, &run->noise.mag}) {
    seconds = std::max(seconds, t->span_s());
    samples = std::max(samples, t->samples());
  }
  reply["state"] = action == "stop" ? "stopped" : "measuring";
  reply["started"] = run->started;
  reply["seconds"] = seconds;
  reply["samples"] = samples;
  reply["poses_announced"] = run->poses_announced;
  if (run->poses_announced > 0) {
    reply["warning"] = fmt::format(
        "the table was sent {} pose(s) during the measurement: not a rest, the long cluster "
        "times hold the moves",
        run->poses_announced);
  }
  reply["axes"] = RestNoiseAxesJson(axes);
  if (action == "stop") {
    run.reset();
    if (!options_.state_dir.empty()) {
      std::error_code ec;
      const std::filesystem::path dir = std::filesystem::path(options_.state_dir) / "rest_noise";
      std::filesystem::create_directories(dir, ec);
      const std::string path =
          UniqueStamped(dir, device + ".", reply["started"].get<std::string>(), ".json").string();
      std::string error;
      if (!ec && WriteFileAtomically(path, reply.dump(1) + "\n", &error)) {
        reply["file"] = path;
      } else {
        reply["save_error"] = ec ? ec.message() : error;
      }
    }
  }
  return reply;
}

}  // namespace turncal::daemon
