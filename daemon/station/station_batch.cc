// The session's batch slot by slot (issue 38; docs/BATCH.md): Station::BatchStatus, which
// `status` and `turncal status`/`watch` show and the report's batch summary reads.

#include <fmt/format.h>

#include <cmath>

#include "daemon/station/station.h"

namespace turncal::daemon {

nlohmann::json Station::BatchStatus() const {
  nlohmann::json units = nlohmann::json::array();
  int passed = 0, waiting = 0, held = 0;
  double last_gate_s = 0.0;
  for (const auto& d : devices_) {
    nlohmann::json u = {
        {"device", d->name},
        {"slot", d->slot.empty() ? nlohmann::json() : nlohmann::json(d->slot)},
        {"serial", d->Serial().empty() ? nlohmann::json() : nlohmann::json(d->Serial())},
        {"poses", d->poses},
        {"seconds", nlohmann::json()}};
    // The first calibration short of its gate, and why.
    std::string short_of;
    bool all_active = d->calibrations->size() > 0;
    for (std::size_t i = 0; i < d->calibrations->size(); ++i) {
      const Calibration& c = d->calibrations->at(i);
      all_active = all_active && c.active_version() > 0;
      if (!short_of.empty() || c.GatePassed()) continue;
      const std::vector<std::string> reasons = c.GateReasons();
      short_of =
          c.name() + (reasons.empty() ? std::string(": no estimate yet") : ": " + reasons.front());
    }
    if (!d->duplicate_serial_of.empty()) {
      u["state"] = "held";
      u["why"] = fmt::format("reports the serial of {}", d->duplicate_serial_of);
      ++held;
    } else if (d->mount_check.wrong) {
      u["state"] = "held";
      u["why"] = d->MountProblem();
      ++held;
    } else if (short_of.empty() && all_active) {
      u["state"] = "passed";
      if (std::isfinite(d->passed_t_s) && std::isfinite(batch_t0_s_)) {
        u["seconds"] = d->passed_t_s - batch_t0_s_;
        last_gate_s = std::max(last_gate_s, d->passed_t_s - batch_t0_s_);
      }
      ++passed;
    } else {
      u["state"] = "waiting";
      u["why"] = d->poses == 0      ? std::string("no pose yet")
                 : short_of.empty() ? std::string("every gate passed; activation under way")
                                    : short_of;
      ++waiting;
    }
    units.push_back(std::move(u));
  }
  nlohmann::json j = batch_.Json();
  j["units"] = units;
  j["passed"] = passed;
  j["waiting"] = waiting;
  j["held"] = held;
  j["seconds_to_last_gate"] = !devices_.empty() && passed == static_cast<int>(devices_.size())
                                  ? nlohmann::json(last_gate_s)
                                  : nlohmann::json();
  return j;
}

}  // namespace turncal::daemon
