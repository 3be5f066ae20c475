#include "protocol/pose_json.h"

#include <fmt/format.h>

#include <cmath>

#include "core/frames/units.h"

namespace turncal::protocol {

nlohmann::json ToJson(const TablePose& p) {
  nlohmann::json j = {{"phi_deg", p.phi_rad * kDegPerRad},
                      {"gamma_deg", p.gamma_rad * kDegPerRad},
                      {"psi_deg", p.psi_rad * kDegPerRad}};
  if (p.is_rate()) {
    j["rate_axis"] = ToString(p.rate_axis);
    j["rate_dps"] = p.rate_radps * kDegPerRad;
  }
  return j;
}

bool ParseTablePose(const nlohmann::json& j, TablePose* out, std::string* error,
                    bool rotating_angle_optional) {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!j.is_object()) return fail("a pose is an object with phi_deg, gamma_deg and psi_deg");
  TablePose p;
  if (const auto it = j.find("rate_axis"); it != j.end()) {
    if (!it->is_string() || !TableAxisFromString(it->get<std::string>(), &p.rate_axis)) {
      return fail("'rate_axis' must be \"outer\", \"middle\" or \"inner\"");
    }
    const auto r = j.find("rate_dps");
    if (r == j.end() || !r->is_number() || !std::isfinite(r->get<double>()) ||
        r->get<double>() == 0.0) {
      return fail("'rate_dps' must be a finite non-zero number (deg/s)");
    }
    p.rate_radps = r->get<double>() * kRadPerDeg;
  } else if (j.contains("rate_dps")) {
    return fail("'rate_dps' needs 'rate_axis'");
  }
  const char* const keys[] = {"phi_deg", "gamma_deg", "psi_deg"};
  const TableAxis by_key[] = {TableAxis::kInner, TableAxis::kMiddle, TableAxis::kOuter};
  double* slots[] = {&p.phi_rad, &p.gamma_rad, &p.psi_rad};
  for (int i = 0; i < 3; ++i) {
    const auto it = j.find(keys[i]);
    if (it == j.end() && rotating_angle_optional && p.rate_axis == by_key[i]) continue;
    if (it == j.end() || !it->is_number() || !std::isfinite(it->get<double>())) {
      return fail(fmt::format("'{}' must be a finite number (degrees)", keys[i]));
    }
    *slots[i] = it->get<double>() * kRadPerDeg;
  }
  *out = p;
  return true;
}

}  // namespace turncal::protocol
