#include "protocol/sequencer_json.h"

#include <fmt/format.h>

#include <cmath>

#include "core/frames/units.h"
#include "protocol/calibration_json.h"
#include "protocol/json_vec3.h"
#include "protocol/move_json.h"
#include "protocol/pose_json.h"

namespace turncal::protocol {
namespace {

nlohmann::json Triad(const TriadStats& s) {
  nlohmann::json cov = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) cov.push_back(JsonVec3(s.covariance.row(r).transpose()));
  nlohmann::json j = {{"mean", JsonVec3(s.mean)}, {"covariance", cov}, {"count", s.count}};
  if (s.values > 0) j["values"] = s.values;
  return j;
}

}  // namespace

bool ParsePoseCommand(const nlohmann::json& j, std::int64_t t_host_ns, Announcement* out,
                      bool* is_pose, std::string* error) {
  *is_pose = false;
  if (!j.is_object()) return false;
  const auto kind = j.find(j.contains("event") ? "event" : "cmd");
  if (kind == j.end() || !kind->is_string()) return false;
  const std::string name = kind->get<std::string>();
  if (name != "pose" && name != "rate") return false;
  *is_pose = true;
  const bool rate = name == "rate";
  Announcement a;
  a.t_host_ns = t_host_ns;
  std::string why;
  nlohmann::json pose = j;
  if (rate) {
    // A controller's command names the axis "axis"; a capture's event writes "rate_axis".
    if (j.contains("axis")) pose["rate_axis"] = j["axis"];
    if (!pose.contains("rate_axis") || !pose.contains("rate_dps")) {
      if (error) {
        *error = "rate: needs 'axis' (\"outer\", \"middle\" or \"inner\") and 'rate_dps'";
      }
      return false;
    }
  } else if (j.contains("rate_axis") || j.contains("rate_dps")) {
    if (error) *error = "pose: a rate segment is the \"rate\" command";
    return false;
  }
  if (!ParseTablePose(pose, &a.pose, &why, /*rotating_angle_optional=*/true)) {
    if (error) *error = name + ": " + why;
    return false;
  }
  if (const auto it = j.find("index"); it != j.end()) {
    const bool in_range = (it->is_number_unsigned() && it->get<std::uint64_t>() <= 2147483647u) ||
                          (it->is_number_integer() && !it->is_number_unsigned() &&
                           it->get<std::int64_t>() >= 0 && it->get<std::int64_t>() <= 2147483647);
    if (!in_range) {
      if (error) *error = name + ": 'index' must be an integer in [0, 2147483647]";
      return false;
    }
    a.index = static_cast<int>(it->get<std::int64_t>());
  }
  if (const auto it = j.find("dwell_s"); it != j.end()) {
    if (!it->is_number() || !(it->get<double>() > 0) || !(it->get<double>() <= 3600)) {
      if (error) *error = name + ": 'dwell_s' must be a number in (0, 3600] (seconds)";
      return false;
    }
    a.dwell_s = it->get<double>();
  }
  *out = a;
  return true;
}

nlohmann::json ToJson(const PoseRecord& r, bool move_blocks) {
  nlohmann::json j = {
      {"pose", protocol::ToJson(r.pose)}, {"t_start", r.t_start_s}, {"t_end", r.t_end_s}};
  if (r.acc) j["acc"] = Triad(*r.acc);
  if (r.gyr) j["gyr"] = Triad(*r.gyr);
  if (r.mag) j["mag"] = Triad(*r.mag);
  if (r.temp_c) j["temp"] = *r.temp_c;
  if (r.temp_spread) {
    j["temp_spread"] = {{"std", r.temp_spread->std_c},
                        {"min", r.temp_spread->min_c},
                        {"max", r.temp_spread->max_c}};
  }
  if (r.has_sensor_window()) {
    j["t_sensor_start"] = r.sensor_t_start_s;
    j["t_sensor_end"] = r.sensor_t_end_s;
  }
  if (r.move_in) j["move_in"] = ToJson(*r.move_in, move_blocks);
  if (r.in_motion) j["in_motion"] = true;
  return j;
}

namespace {

bool ReadTriad(const nlohmann::json& j, TriadStats* t) {
  if (!j.is_object() || !j.contains("mean") || !j.contains("covariance") || !j.contains("count")) {
    return false;
  }
  if (!ReadJsonVec3(j["mean"], &t->mean) || !j["count"].is_number_integer()) return false;
  t->count = j["count"].get<std::int64_t>();
  const auto& c = j["covariance"];
  if (!c.is_array() || c.size() != 3 || t->count < 1) return false;
  // A triad that held its values (absent in journals written before it was counted: samples).
  if (j.contains("values")) {
    if (!j["values"].is_number_integer()) return false;
    t->values = j["values"].get<std::int64_t>();
    if (t->values < 2 || t->values > t->count) return false;
  }
  for (int r = 0; r < 3; ++r) {
    Eigen::Vector3d row;
    if (!ReadJsonVec3(c[static_cast<std::size_t>(r)], &row)) return false;
    t->covariance.row(r) = row.transpose();
  }
  return true;
}

}  // namespace

bool ParsePoseRecord(const nlohmann::json& j, PoseRecord* out, std::string* error) {
  auto fail = [&](const char* what) {
    if (error) *error = std::string("pose record: ") + what;
    return false;
  };
  if (!j.is_object()) return fail("not an object");
  PoseRecord r;
  if (std::string why; !ParseTablePose(j.value("pose", nlohmann::json()), &r.pose, &why)) {
    if (error) *error = "pose record: " + why;
    return false;
  }
  if (!j.contains("t_start") || !j.contains("t_end") || !j["t_start"].is_number() ||
      !j["t_end"].is_number()) {
    return fail("window times missing");
  }
  r.t_start_s = j["t_start"].get<double>();
  r.t_end_s = j["t_end"].get<double>();
  if (j.contains("t_sensor_start") && j.contains("t_sensor_end") &&
      j["t_sensor_start"].is_number() && j["t_sensor_end"].is_number()) {
    r.sensor_t_start_s = j["t_sensor_start"].get<double>();
    r.sensor_t_end_s = j["t_sensor_end"].get<double>();
  }
  const char* const triads[] = {"acc", "gyr", "mag"};
  std::optional<TriadStats>* slots[] = {&r.acc, &r.gyr, &r.mag};
  for (int i = 0; i < 3; ++i) {
    if (!j.contains(triads[i])) continue;
    TriadStats t;
    if (!ReadTriad(j[triads[i]], &t)) return fail("a triad is malformed");
    *slots[i] = t;
  }
  if (j.contains("temp")) {
    if (!j["temp"].is_number()) return fail("temp is not a number");
    r.temp_c = j["temp"].get<double>();
  }
  if (j.contains("temp_spread")) {
    const nlohmann::json& t = j["temp_spread"];
    if (!t.is_object() || !t.value("std", nlohmann::json()).is_number() ||
        !t.value("min", nlohmann::json()).is_number() ||
        !t.value("max", nlohmann::json()).is_number()) {
      return fail("temp_spread is not {std, min, max}");
    }
    r.temp_spread =
        TemperatureSpread{t["std"].get<double>(), t["min"].get<double>(), t["max"].get<double>()};
  }
  if (j.contains("in_motion")) {
    if (!j["in_motion"].is_boolean()) return fail("in_motion is not true or false");
    r.in_motion = j["in_motion"].get<bool>();
  }
  // A move without its blocks (an event's summary) is left out: nothing to calibrate from.
  if (j.contains("move_in") && j["move_in"].contains("increment_rad")) {
    MoveRecord m;
    std::string why;
    if (!ParseMoveRecord(j["move_in"], &m, &why)) {
      if (error) *error = "pose record: " + why;
      return false;
    }
    r.move_in = std::move(m);
  }
  *out = r;
  return true;
}

nlohmann::json ToJson(const NoiseProfile& p) {
  nlohmann::json sigma = nlohmann::json::object();
  for (int t = 0; t < 3; ++t) {
    if (p.sigma[t]) sigma[TriadName(t)] = JsonVec3(*p.sigma[t]);
  }
  nlohmann::json j = {{"sigma", sigma},
                      {"gyr_bias_radps", JsonVec3(p.gyr_bias_radps)},
                      {"gyr_bias_sigma_radps", p.gyr_bias_sigma_radps},
                      {"rate_hz", p.rate_hz},
                      {"source", p.source}};
  if (p.device_period_s) j["device_period_s"] = *p.device_period_s;
  if (std::isfinite(p.sigma_dof)) j["sigma_dof"] = p.sigma_dof;
  if (p.measured_host_s) {
    j["measured_host_s"] = {p.measured_host_s->first, p.measured_host_s->second};
  }
  if (std::isfinite(p.gyr_bias_temp_c)) j["gyr_bias_temp_c"] = p.gyr_bias_temp_c;
  nlohmann::json lag_one = nlohmann::json::object();
  for (int t = 0; t < 3; ++t) {
    const double rho = p.lag_one[static_cast<std::size_t>(t)];
    if (p.sigma[t] && rho != 0.0) lag_one[TriadName(t)] = rho;
  }
  if (!lag_one.empty()) j["lag_one"] = lag_one;
  nlohmann::json identified = nlohmann::json::object();
  for (int t = 0; t < 3; ++t) {
    const auto& d = p.identified_drift[static_cast<std::size_t>(t)];
    if (!d) continue;
    identified[TriadName(t)] = {
        {"drift", ToJson(d->drift)}, {"scale", d->scale}, {"poses", d->poses}};
  }
  if (!identified.empty()) j["identified_drift"] = identified;
  return j;
}

bool ParseNoiseProfile(const nlohmann::json& j, NoiseProfile* out, std::string* error) {
  auto fail = [&](const char* what) {
    if (error) *error = std::string("noise profile: ") + what;
    return false;
  };
  if (!j.is_object() || !j.contains("sigma") || !j["sigma"].is_object()) {
    return fail("no sigma");
  }
  NoiseProfile p;
  for (int t = 0; t < 3; ++t) {
    if (!j["sigma"].contains(TriadName(t))) continue;
    Eigen::Vector3d v;
    if (!ReadJsonVec3(j["sigma"][TriadName(t)], &v)) return fail("a sigma is malformed");
    p.sigma[t] = v;
  }
  if (!j.contains("gyr_bias_radps") || !ReadJsonVec3(j["gyr_bias_radps"], &p.gyr_bias_radps)) {
    return fail("gyro bias malformed");
  }
  if (!j.contains("rate_hz") || !j["rate_hz"].is_number() || !j.contains("gyr_bias_sigma_radps") ||
      !j["gyr_bias_sigma_radps"].is_number()) {
    return fail("rate or gyro bias sigma missing");
  }
  p.rate_hz = j["rate_hz"].get<double>();
  p.gyr_bias_sigma_radps = j["gyr_bias_sigma_radps"].get<double>();
  if (j.contains("device_period_s") && j["device_period_s"].is_number()) {
    p.device_period_s = j["device_period_s"].get<double>();
  }
  if (j.contains("sigma_dof") && j["sigma_dof"].is_number()) {
    p.sigma_dof = j["sigma_dof"].get<double>();
  }
  if (j.contains("measured_host_s") && j["measured_host_s"].is_array() &&
      j["measured_host_s"].size() == 2 && j["measured_host_s"][0].is_number() &&
      j["measured_host_s"][1].is_number()) {
    p.measured_host_s = std::make_pair(j["measured_host_s"][0].get<double>(),
                                       j["measured_host_s"][1].get<double>());
  }
  if (j.contains("gyr_bias_temp_c") && j["gyr_bias_temp_c"].is_number()) {
    p.gyr_bias_temp_c = j["gyr_bias_temp_c"].get<double>();
  }
  if (j.contains("lag_one")) {
    const auto& lag_one = j["lag_one"];
    if (!lag_one.is_object()) return fail("lag_one malformed");
    for (int t = 0; t < 3; ++t) {
      if (!lag_one.contains(TriadName(t))) continue;
      const auto& rho = lag_one[TriadName(t)];
      if (!rho.is_number() || !(std::abs(rho.get<double>()) < 1)) {
        return fail("a lag-one correlation is not a number in (-1, 1)");
      }
      p.lag_one[static_cast<std::size_t>(t)] = rho.get<double>();
    }
  }
  if (j.contains("identified_drift")) {
    const auto& identified = j["identified_drift"];
    if (!identified.is_object()) return fail("identified_drift malformed");
    for (int t = 0; t < 3; ++t) {
      if (!identified.contains(TriadName(t))) continue;
      const auto& e = identified[TriadName(t)];
      IdentifiedDrift d;
      if (!e.is_object() || !e.contains("drift") || !ParseBiasDrift(e["drift"], &d.drift) ||
          !e.contains("scale") || !e["scale"].is_number() || !(e["scale"].get<double>() > 0)) {
        return fail("an identified drift is malformed");
      }
      d.scale = e["scale"].get<double>();
      d.poses = e.value("poses", 0);
      p.identified_drift[static_cast<std::size_t>(t)] = d;
    }
  }
  p.source = j.value("source", std::string("stored")) + " (stored)";
  if (!p.IsValid(error)) return false;
  *out = p;
  return true;
}

nlohmann::json ToJson(const SequencerEvent& e) {
  nlohmann::json j = {{"class", ToString(e.kind)}, {"t", e.t_s}};
  if (e.index >= 0) {
    j["index"] = e.index;
    j["pose"] = protocol::ToJson(e.pose);
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
  if (e.record) j["record"] = ToJson(*e.record, /*move_blocks=*/false);
  return j;
}

}  // namespace turncal::protocol
