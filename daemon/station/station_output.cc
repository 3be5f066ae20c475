// What the station gives out: live samples corrected with the applied calibrations, and the
// answers to `status`, `result`, `next_pose` and `publish` (an operator's override).

#include <fmt/format.h>

#include "daemon/station/station.h"

#include "daemon/station/pose_calibrations.h"
#include "protocol/observability_json.h"

namespace turncal::daemon {

bool Station::HasAppliedCalibration(int device) const {
  const CalibrationSet& set = *devices_[static_cast<std::size_t>(device)]->calibrations;
  for (std::size_t i = 0; i < set.size(); ++i) {
    if (set.at(i).applied_version() > 0) return true;
  }
  return false;
}

bool Station::Correct(int device, const Sample& sample, Corrected* out, bool with_sigma) const {
  *out = Corrected{};
  const CalibrationSet& set = *devices_[static_cast<std::size_t>(device)]->calibrations;
  const double t_s = static_cast<double>(sample.t_host_ns) * 1e-9;
  for (std::size_t i = 0; i < set.size(); ++i) {
    const Calibration& c = set.at(i);
    if (c.applied_version() <= 0) continue;
    const int triad = c.triad();
    const std::optional<Eigen::Vector3d>& raw = RawTriad(sample, triad);
    std::optional<Eigen::Vector3d>& target = triad == kTriadAcc   ? out->acc_mps2
                                             : triad == kTriadGyr ? out->gyr_radps
                                                                  : out->mag;
    if (!raw || target) continue;  // the first calibration of a triad in the configured order wins
    std::optional<Eigen::Vector3d>& sigma = triad == kTriadAcc   ? out->acc_sigma
                                            : triad == kTriadGyr ? out->gyr_sigma
                                                                 : out->mag_sigma;
    const char*& frame = triad == kTriadAcc   ? out->acc_frame
                         : triad == kTriadGyr ? out->gyr_frame
                                              : out->mag_frame;
    Eigen::Vector3d value;
    if (!c.Correct(sample, t_s, &value, with_sigma ? &sigma : nullptr, &frame)) continue;
    target = value;
    out->versions.emplace_back(c.name(), c.applied_version());
    if (const char* flag = c.TemperatureFlag(sample)) {
      out->temperature_flags.emplace_back(c.name(), flag);
    }
  }
  return !out->versions.empty();
}

nlohmann::json Station::Status(int device) const {
  return devices_[static_cast<std::size_t>(device)]->StatusJson();
}

bool Station::PublishOverride(const std::string& device, const std::string& model,
                              const nlohmann::json& who, std::string* error) {
  const int i = DeviceIndex(device);
  if (i < 0) {
    *error = "no device '" + device + "'";
    return false;
  }
  DeviceState& d = *devices_[static_cast<std::size_t>(i)];
  Calibration* c = d.calibrations->Find(model);
  if (!c) {
    *error = fmt::format("device '{}' estimates no model '{}'", device, model);
    return false;
  }
  std::string why;
  if (!c->HasEstimate(&why)) {
    *error = fmt::format("{} {} has no estimate to publish{}", device, model,
                         why.empty() ? "" : ": " + why);
    return false;
  }
  nlohmann::json record = who;
  record["gate_pass"] = c->GatePassed();
  record["gate_reasons"] = c->GateReasons();
  Activate(d, *c, 0.0, record);
  return true;
}

nlohmann::json Station::NextPose(const std::string& device) const {
  const int i = DeviceIndex(device);
  if (i < 0)
    return {{"class", "NEXT_POSE"}, {"ok", false}, {"error", "no device '" + device + "'"}};
  const DeviceState& d = *devices_[static_cast<std::size_t>(i)];
  nlohmann::json j = d.calibrations->NextPose(d, options_);
  j["device"] = device;
  return j;
}

nlohmann::json Station::NextPoseBatch() const {
  // Every unit still short of a gate plans together: the table's next pose for the whole fixture
  // (the information of all units and all their models), so the session ends at the last unit's
  // gate. A unit whose gates have all passed does not hold the others back, and a unit that
  // does not sit as its mount says (its information would be the wrong slot's) waits for its fix.
  std::vector<PlanningTarget> targets;
  std::vector<std::string> target_device;
  nlohmann::json units = nlohmann::json::array();
  const DeviceState* lead = nullptr;
  int waiting = 0;
  for (const auto& d : devices_) {
    bool passed = d->calibrations->size() > 0;
    for (std::size_t i = 0; i < d->calibrations->size(); ++i) {
      passed = passed && d->calibrations->at(i).GatePassed();
    }
    // Only a unit that is planned for takes its calibrators' locks for its targets.
    std::vector<PlanningTarget> own;
    if (!passed && !d->mount_check.wrong) {
      own = d->calibrations->PlanningTargets(*d, options_.sequencer.dwell_s);
    }
    const char* state = passed                 ? "passed"
                        : d->mount_check.wrong ? "mount wrong"
                        : own.empty()          ? "nothing to plan"
                                               : "planned";
    units.push_back({{"device", d->name},
                     {"slot", d->slot.empty() ? nlohmann::json() : nlohmann::json(d->slot)},
                     {"poses", d->poses},
                     {"state", state}});
    if (std::string(state) != "planned") continue;
    ++waiting;
    if (!lead) lead = d.get();
    for (auto& t : own) {
      targets.push_back(std::move(t));
      target_device.push_back(d->name);
    }
  }
  nlohmann::json j;
  if (!lead) {
    j = {{"class", "NEXT_POSE"},
         {"ok", false},
         {"error", devices_.empty() ? "no device" : "no unit of the batch needs a pose"}};
  } else {
    j = ToJson(PlanNextPose(targets, PoseCalibrations::PlannerFor(*lead, options_)));
    if (j.contains("models")) {
      for (std::size_t k = 0; k < j["models"].size() && k < target_device.size(); ++k) {
        j["models"][k]["device"] = target_device[k];
      }
    }
  }
  j["batch"] = {{"units", units}, {"planned", waiting}, {"fixture", options_.fixture}};
  return j;
}

nlohmann::json Station::Result() const {
  nlohmann::json devices = nlohmann::json::object();
  for (const auto& d : devices_) devices[d->name] = d->ResultJson();
  return {{"class", "RESULT"}, {"batch", BatchStatus()}, {"devices", devices}};
}

}  // namespace turncal::daemon
