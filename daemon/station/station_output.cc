// What the station gives out: live samples corrected with the applied calibrations, and the
// answers to `status`, `result`, `next_pose` and `publish` (an operator's override).

#include <fmt/format.h>

#include "core/planning/pose_planner.h"
#include "daemon/station/station.h"
#include "protocol/observability_json.h"

namespace turncal::daemon {

bool Station::HasAppliedCalibration(int device) const {
  const DeviceState& d = *devices_[static_cast<std::size_t>(device)];
  if (d.free) {
    for (const auto& m : d.free->models) {
      if (m->applied_version > 0) return true;
    }
  }
  for (const ModelState& m : d.models) {
    if (m.applied_version > 0) return true;
  }
  return false;
}

bool Station::Correct(int device, const Sample& sample, Corrected* out, bool with_sigma) const {
  *out = Corrected{};
  const DeviceState& d = *devices_[static_cast<std::size_t>(device)];
  if (d.free) {
    for (const auto& mp : d.free->models) {
      const FreeModelState& m = *mp;
      if (m.applied_version <= 0 || !m.applied_model) continue;
      const int triad = m.triad();
      const std::optional<Eigen::Vector3d>& raw = triad == kTriadAcc   ? sample.acc_mps2
                                                  : triad == kTriadGyr ? sample.gyr_radps
                                                                       : sample.mag;
      std::optional<Eigen::Vector3d>& target = triad == kTriadAcc   ? out->acc_mps2
                                               : triad == kTriadGyr ? out->gyr_radps
                                                                    : out->mag;
      if (!raw || target) continue;  // the first model of a triad in the configured order wins
      std::optional<Eigen::Vector3d>& sigma = triad == kTriadAcc   ? out->acc_sigma
                                              : triad == kTriadGyr ? out->gyr_sigma
                                                                   : out->mag_sigma;
      target =
          m.Correct(*raw, sample.acc_mps2 ? &*sample.acc_mps2 : nullptr,
                    static_cast<double>(sample.t_host_ns) * 1e-9, with_sigma ? &sigma : nullptr);
      (triad == kTriadAcc   ? out->acc_frame
       : triad == kTriadGyr ? out->gyr_frame
                            : out->mag_frame) = FreeOutputFrame(m.applied_model->name());
      out->versions.emplace_back(m.requested, m.applied_version);
    }
    return !out->versions.empty();
  }
  for (const ModelState& m : d.models) {
    if (m.applied_version <= 0) continue;
    const int triad = m.triad();
    const std::optional<Eigen::Vector3d>& raw = triad == kTriadAcc   ? sample.acc_mps2
                                                : triad == kTriadGyr ? sample.gyr_radps
                                                                     : sample.mag;
    if (!raw) continue;
    std::optional<Eigen::Vector3d>& target = triad == kTriadAcc   ? out->acc_mps2
                                             : triad == kTriadGyr ? out->gyr_radps
                                                                  : out->mag;
    if (target) continue;  // the first model of a sensor in the configured order wins
    std::optional<Eigen::Vector3d>& sigma = triad == kTriadAcc   ? out->acc_sigma
                                            : triad == kTriadGyr ? out->gyr_sigma
                                                                 : out->mag_sigma;
    // A gyro's g-sensitivity sees the specific force in the table frame: the raw accelerometer
    // turned back by the nominal mounting (its own errors, ~1e-3, are far below what B_g needs).
    std::optional<Eigen::Vector3d> f_q;
    if (triad == kTriadGyr && sample.acc_mps2) {
      f_q = m.model->context().mounting.transpose() * *sample.acc_mps2;
    }
    target = m.Correct(*raw, static_cast<double>(sample.t_host_ns) * 1e-9,
                       with_sigma ? &sigma : nullptr, f_q ? &*f_q : nullptr);
    (triad == kTriadAcc   ? out->acc_frame
     : triad == kTriadGyr ? out->gyr_frame
                          : out->mag_frame) = ToString(m.model->corrected_frame());
    out->versions.emplace_back(m.model->name(), m.applied_version);
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
  if (d.free) {
    FreeModelState* m = d.free->Find(model);
    if (!m) {
      *error = fmt::format("device '{}' estimates no model '{}'", device, model);
      return false;
    }
    const Estimate& e = m->result.estimate.estimate;
    if (!e.ok) {
      *error = fmt::format("{} {} has no estimate to publish{}", device, model,
                           e.error.empty() ? "" : ": " + e.error);
      return false;
    }
    nlohmann::json record = who;
    record["gate_pass"] = m->result.estimate.gate_passed;
    record["gate_reasons"] = m->result.estimate.gate_reasons;
    ActivateFree(d, *m, 0.0, record);
    return true;
  }
  for (ModelState& m : d.models) {
    if (m.model->name() != model) continue;
    if (!m.estimate.ok) {
      *error = fmt::format("{} {} has no estimate to publish{}", device, model,
                           m.estimate.error.empty() ? "" : ": " + m.estimate.error);
      return false;
    }
    nlohmann::json record = who;
    record["gate_pass"] = m.gate.pass;
    record["gate_reasons"] = m.gate.reasons;
    Activate(d, m, 0.0, record);
    return true;
  }
  *error = fmt::format("device '{}' estimates no model '{}'", device, model);
  return false;
}

nlohmann::json Station::NextPose(const std::string& device) const {
  const int i = DeviceIndex(device);
  if (i < 0)
    return {{"class", "NEXT_POSE"}, {"ok", false}, {"error", "no device '" + device + "'"}};
  const DeviceState& d = *devices_[static_cast<std::size_t>(i)];
  if (d.free) return d.free->NextPoseJson(device);
  const std::vector<PlanningTarget> targets = d.PlanningTargets(options_.sequencer.dwell_s);
  PlannerOptions planner;
  planner.motion = options_.table;
  planner.objective = options_.plan_objective;
  planner.dwell_s = options_.sequencer.dwell_s;
  planner.rates = options_.plan_rates;
  planner.moves = options_.sequencer.moves.enabled;
  // From where the table was last announced; the move into the next pose counts when the
  // sequencer tracks one (a static pose captured there, no rate segment since).
  if (const auto at = d.sequencer->announced()) planner.table_at = *at;
  planner.move_from_table_at = d.sequencer->moves().tracking();
  planner.move_rest_s = d.MoveRestSeconds(options_.table, planner.move_rest_s);
  nlohmann::json j = ToJson(PlanNextPose(targets, planner));
  j["device"] = device;
  return j;
}

nlohmann::json Station::Result() const {
  nlohmann::json devices = nlohmann::json::object();
  for (const auto& d : devices_) devices[d->name] = d->ResultJson();
  return {{"class", "RESULT"}, {"devices", devices}};
}

}  // namespace turncal::daemon
