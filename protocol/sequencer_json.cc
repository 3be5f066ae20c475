#include "protocol/sequencer_json.h"

#include <fmt/format.h>

#include <cmath>

namespace turncal::protocol {
namespace {

constexpr double kDegToRad = M_PI / 180.0;

nlohmann::json Vec(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

nlohmann::json Triad(const TriadStats& s) {
  nlohmann::json cov = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) cov.push_back(Vec(s.covariance.row(r).transpose()));
  return {{"mean", Vec(s.mean)}, {"covariance", cov}, {"count", s.count}};
}

}  // namespace

bool ParsePoseCommand(const nlohmann::json& j, std::int64_t t_host_ns, Announcement* out,
                      bool* is_pose, std::string* error) {
  *is_pose = false;
  if (!j.is_object()) return false;
  const auto kind = j.find(j.contains("event") ? "event" : "cmd");
  if (kind == j.end() || !kind->is_string() || kind->get<std::string>() != "pose") return false;
  *is_pose = true;
  Announcement a;
  a.t_host_ns = t_host_ns;
  double angles[3];
  const char* const keys[] = {"phi_deg", "gamma_deg", "psi_deg"};
  for (int i = 0; i < 3; ++i) {
    const auto it = j.find(keys[i]);
    if (it == j.end() || !it->is_number() || !std::isfinite(it->get<double>())) {
      if (error) *error = fmt::format("pose: '{}' must be a finite number (degrees)", keys[i]);
      return false;
    }
    angles[i] = it->get<double>() * kDegToRad;
  }
  a.pose = TablePose{angles[0], angles[1], angles[2]};
  if (const auto it = j.find("index"); it != j.end()) {
    const bool in_range = (it->is_number_unsigned() && it->get<std::uint64_t>() <= 2147483647u) ||
                          (it->is_number_integer() && !it->is_number_unsigned() &&
                           it->get<std::int64_t>() >= 0 && it->get<std::int64_t>() <= 2147483647);
    if (!in_range) {
      if (error) *error = "pose: 'index' must be an integer in [0, 2147483647]";
      return false;
    }
    a.index = static_cast<int>(it->get<std::int64_t>());
  }
  if (const auto it = j.find("dwell_s"); it != j.end()) {
    if (!it->is_number() || !(it->get<double>() > 0) || !(it->get<double>() <= 3600)) {
      if (error) *error = "pose: 'dwell_s' must be a number in (0, 3600] (seconds)";
      return false;
    }
    a.dwell_s = it->get<double>();
  }
  *out = a;
  return true;
}

nlohmann::json ToJson(const PoseRecord& r) {
  nlohmann::json j = {{"pose",
                       {{"phi_deg", r.pose.phi_rad / kDegToRad},
                        {"gamma_deg", r.pose.gamma_rad / kDegToRad},
                        {"psi_deg", r.pose.psi_rad / kDegToRad}}},
                      {"t_start", r.t_start_s},
                      {"t_end", r.t_end_s}};
  if (r.acc) j["acc"] = Triad(*r.acc);
  if (r.gyr) j["gyr"] = Triad(*r.gyr);
  if (r.mag) j["mag"] = Triad(*r.mag);
  if (r.temp_c) j["temp"] = *r.temp_c;
  return j;
}

nlohmann::json ToJson(const SequencerEvent& e) {
  nlohmann::json j = {{"class", ToString(e.kind)}, {"t", e.t_s}};
  if (e.index >= 0) {
    j["index"] = e.index;
    j["pose"] = {{"phi_deg", e.pose.phi_rad / kDegToRad},
                 {"gamma_deg", e.pose.gamma_rad / kDegToRad},
                 {"psi_deg", e.pose.psi_rad / kDegToRad}};
  }
  if (e.needed > 0) {
    j["collected"] = e.collected;
    j["needed"] = e.needed;
    j["counts"] = {{"used", e.counts.used},
                   {"flagged", e.counts.flagged},
                   {"outliers", e.counts.outliers},
                   {"lost", e.counts.lost}};
  }
  if (!e.reason.empty()) j["reason"] = e.reason;
  if (e.record) j["record"] = ToJson(*e.record);
  return j;
}

}  // namespace turncal::protocol
