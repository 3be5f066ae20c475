#include "daemon/service/config.h"

#include <fmt/format.h>

#include <toml++/toml.h>
#include <cmath>

#include <fstream>
#include <set>
#include <sstream>
#include "daemon/service/config_toml.h"
#include "daemon/service/socket_server.h"

namespace turncal::daemon {
namespace {

bool ParseTable(const toml::table& t, const std::string& source, StationOptions* st,
                std::string* error) {
  if (!OnlyKeys(t,
                {"rate_dps", "accel_dps2", "settle_s", "plan_for", "rate_accuracy", "rate_ripple",
                 "plan_rates_dps"},
                "[table]", source, error) ||
      !GetAxes(t, "rate_dps", &st->table.rate_dps, source, error) ||
      !GetAxes(t, "accel_dps2", &st->table.accel_dps2, source, error) ||
      !GetNumber(t, "settle_s", &st->table.settle_s, source, error) ||
      !GetNumber(t, "rate_accuracy", &st->rate_accuracy, source, error) ||
      !GetNumber(t, "rate_ripple", &st->sequencer.rate_steady.ripple, source, error) ||
      !GetNumberList(t, "plan_rates_dps", &st->plan_rates.rates_dps, source, error)) {
    return false;
  }
  std::string why;
  if (!st->table.IsValid(&why) || !st->plan_rates.IsValid(&why)) {
    *error = fmt::format("{}: [table] {}", source, why);
    return false;
  }
  std::string plan_for = ToString(st->plan_objective);
  if (!GetString(t, "plan_for", &plan_for, source, error)) return false;
  if (plan_for != "time" && plan_for != "poses") {
    *error = fmt::format("{}: [table] plan_for must be \"time\" or \"poses\"", source);
    return false;
  }
  st->plan_objective = plan_for == "time" ? PlanObjective::kTime : PlanObjective::kPoses;
  return true;
}

// [gate] or a device's [device.gate]: tolerances over `gate`'s current values.
bool ParseGate(const toml::table& t, const std::string& context, const std::string& source,
               GateOptions* gate, std::string* error) {
  if (!OnlyKeys(t,
                {"scale_factor", "angle_deg", "acceleration_mps2", "gain", "field",
                 "angular_rate_deg_h", "g_sensitivity_deg_h_g", "second_order_ug_g2", "min_p_value",
                 "min_dof", "max_normalized_residual", "parameters"},
                context, source, error)) {
    return false;
  }
  GateTolerances& g = gate->tolerances;
  double angle_deg = g.angle_rad * 180 / M_PI;
  constexpr double kDegPerHour = M_PI / 180 / 3600;
  double rate_deg_h = g.angular_rate_radps / kDegPerHour;
  double gsens_deg_h_g = g.g_sensitivity * kStandardGravity_mps2 / kDegPerHour;
  double k2_ug_g2 = g.second_order * kStandardGravity_mps2 * 1e6;
  if (!GetNumber(t, "scale_factor", &g.scale_factor, source, error) ||
      !GetNumber(t, "angular_rate_deg_h", &rate_deg_h, source, error) ||
      !GetNumber(t, "g_sensitivity_deg_h_g", &gsens_deg_h_g, source, error) ||
      !GetNumber(t, "second_order_ug_g2", &k2_ug_g2, source, error) ||
      !GetNumber(t, "angle_deg", &angle_deg, source, error) ||
      !GetNumber(t, "acceleration_mps2", &g.acceleration_mps2, source, error) ||
      !GetNumber(t, "gain", &g.gain, source, error) ||
      !GetNumber(t, "field", &g.field, source, error) ||
      !GetNumber(t, "min_p_value", &gate->min_p_value, source, error) ||
      !GetInt(t, "min_dof", &gate->min_dof, source, error) ||
      !GetNumber(t, "max_normalized_residual", &gate->max_normalized_residual, source, error)) {
    return false;
  }
  g.angle_rad = angle_deg * M_PI / 180;
  g.angular_rate_radps = rate_deg_h * kDegPerHour;
  g.g_sensitivity = gsens_deg_h_g * kDegPerHour / kStandardGravity_mps2;
  g.second_order = k2_ug_g2 * 1e-6 / kStandardGravity_mps2;
  if (const toml::table* p = t["parameters"].as_table()) {
    for (const auto& [key, node] : *p) {
      auto v = node.value<double>();
      if (!v || !(*v > 0)) {
        *error = fmt::format("{}: gate tolerance '{}' must be a number > 0", Where(node, source),
                             key.str());
        return false;
      }
      gate->parameter_tolerance[std::string(key.str())] = *v;
    }
  }
  if (!gate->IsValid(error)) {
    *error = fmt::format("{}: {}: {}", Where(t, source), context, *error);
    return false;
  }
  return true;
}

// [registry]: the connection string is required (a registry without one is a typo), the rest
// has defaults (daemon/registry/registry_options.h).
bool ParseRegistry(const toml::table& t, const std::string& source, RegistryOptions* out,
                   std::string* error) {
  if (!OnlyKeys(t, {"conninfo", "password_file", "station", "retry_max_s", "connect_timeout_s"},
                "[registry]", source, error) ||
      !GetString(t, "conninfo", &out->conninfo, source, error) ||
      !GetString(t, "password_file", &out->password_file, source, error) ||
      !GetString(t, "station", &out->station, source, error) ||
      !GetNumber(t, "retry_max_s", &out->retry_max_s, source, error)) {
    return false;
  }
  double timeout_s = out->connect_timeout_s;
  if (!GetNumber(t, "connect_timeout_s", &timeout_s, source, error)) return false;
  if (out->conninfo.empty()) {
    *error = fmt::format(
        "{}: [registry] needs conninfo, a libpq connection string (\"host=db dbname=turncal\")",
        source);
    return false;
  }
  if (!(out->retry_max_s >= 1) || !(timeout_s >= 1 && timeout_s <= 300)) {
    *error = fmt::format(
        "{}: [registry] retry_max_s must be >= 1, connect_timeout_s between 1 and 300", source);
    return false;
  }
  out->connect_timeout_s = static_cast<int>(timeout_s);
  return true;
}

// [station]: the models, the pose source, the sensor class, the drift model and the noise prior.
bool ParseStation(const toml::table* t, const std::string& source, Config* out,
                  std::string* error) {
  Config& c = *out;
  StationOptions& st = c.station;
  if (!OnlyKeys(
          *t,
          {"models", "pose_source", "sensor_class", "drift_model", "identify_drift", "bias_tau_s",
           "warmup", "warmup_tau_s", "acc_noise_density", "acc_bias_instability", "mag_noise_rms",
           "mag_bias_instability", "acc_random_walk", "mag_random_walk"},
          "[station]", source, error)) {
    return false;
  }
  if (!GetString(*t, "sensor_class", &st.sensor_class, source, error)) return false;
  std::string drift_model = "gauss-markov";
  if (!GetString(*t, "drift_model", &drift_model, source, error)) return false;
  if (drift_model != "gauss-markov" && drift_model != "independent") {
    *error = fmt::format("{}: [station] drift_model must be \"gauss-markov\" or \"independent\"",
                         source);
    return false;
  }
  st.drift_model = drift_model == "gauss-markov";
  if (const toml::node* n = t->get("identify_drift")) {
    const auto* v = n->as_boolean();  // not value<bool>(), which takes 1 for true
    if (!v) {
      *error = fmt::format("{}: 'identify_drift' must be true or false", Where(*n, source));
      return false;
    }
    st.identify_drift = v->get();
  }
  if (!GetNumber(*t, "bias_tau_s", &st.bias_tau_s, source, error) ||
      !GetNumber(*t, "warmup", &st.warmup_in_instabilities, source, error) ||
      !GetNumber(*t, "warmup_tau_s", &st.warmup_tau_s, source, error)) {
    return false;
  }
  if ((t->contains("bias_tau_s") && !(st.bias_tau_s > 0)) ||
      (t->contains("warmup") && !(st.warmup_in_instabilities >= 0)) ||
      (t->contains("warmup_tau_s") && !(st.warmup_tau_s > 0))) {
    *error =
        fmt::format("{}: [station] bias_tau_s and warmup_tau_s must be > 0, warmup >= 0", source);
    return false;
  }
  // The noise prior measured on this sensor (turncal noise): densities and instabilities > 0,
  // random walks >= 0.
  const std::pair<const char*, double*> noise[] = {
      {"acc_noise_density", &st.acc_noise_density},
      {"acc_bias_instability", &st.acc_bias_instability},
      {"mag_noise_rms", &st.mag_noise_rms},
      {"mag_bias_instability", &st.mag_bias_instability},
      {"acc_random_walk", &st.acc_random_walk},
      {"mag_random_walk", &st.mag_random_walk}};
  for (const auto& [key, value] : noise) {
    if (!GetNumber(*t, key, value, source, error)) return false;
    const bool walk = std::string_view(key).find("random_walk") != std::string_view::npos;
    if (t->contains(key) && !(walk ? *value >= 0 : *value > 0)) {
      *error = fmt::format("{}: [station] {} must be {} (turncal noise fits it from a long rest)",
                           source, key, walk ? ">= 0" : "> 0");
      return false;
    }
  }
  std::string pose_source = "announced";
  if (!GetString(*t, "pose_source", &pose_source, source, error)) return false;
  if (!ParsePoseSource(pose_source, &st.pose_source)) {
    *error = fmt::format("{}: [station] pose_source must be \"announced\" or \"free\"", source);
    return false;
  }
  c.models_set = t->contains("models");
  if (!GetModels(*t, &st.models, source, error)) return false;
  return true;
}

// [sequencer]: stillness, the dwell, the pose check, the moves.
bool ParseSequencer(const toml::table* t, const std::string& source, Config* out,
                    std::string* error) {
  Config& c = *out;
  StationOptions& st = c.station;
  if (!OnlyKeys(*t,
                {"dwell_s", "window_s", "settle_guard_s", "still_timeout_s", "startup_s",
                 "max_bad_fraction", "max_lost_fraction", "false_alarm", "outlier_k",
                 "gyr_bias_drift_radps", "pose_check_false_alarm", "moves", "move_block_s",
                 "move_max_s", "free_max_dwell_s"},
                "[sequencer]", source, error)) {
    return false;
  }
  SequencerOptions& q = st.sequencer;
  c.dwell_set = t->contains("dwell_s");
  if (!GetNumber(*t, "dwell_s", &q.dwell_s, source, error) ||
      !GetNumber(*t, "window_s", &q.stillness.window_s, source, error) ||
      !GetNumber(*t, "settle_guard_s", &q.settle_guard_s, source, error) ||
      !GetNumber(*t, "still_timeout_s", &q.still_timeout_s, source, error) ||
      !GetNumber(*t, "startup_s", &q.noise_meter.duration_s, source, error) ||
      !GetNumber(*t, "max_bad_fraction", &q.max_bad_fraction, source, error) ||
      !GetNumber(*t, "max_lost_fraction", &q.max_lost_fraction, source, error) ||
      !GetNumber(*t, "false_alarm", &q.stillness.false_alarm, source, error) ||
      !GetNumber(*t, "outlier_k", &q.stillness.outlier_k, source, error) ||
      !GetNumber(*t, "gyr_bias_drift_radps", &q.stillness.gyr_bias_drift_radps, source, error) ||
      !GetNumber(*t, "pose_check_false_alarm", &q.pose_check_false_alarm, source, error) ||
      !GetNumber(*t, "move_block_s", &q.moves.block_s, source, error) ||
      !GetNumber(*t, "move_max_s", &q.moves.max_s, source, error) ||
      !GetNumber(*t, "free_max_dwell_s", &q.free_max_dwell_s, source, error)) {
    return false;
  }
  if (const toml::node* n = t->get("moves")) {
    const auto* v = n->as_boolean();
    if (!v) {
      *error = fmt::format("{}: 'moves' must be true or false", Where(*n, source));
      return false;
    }
    q.moves.enabled = v->get();
  }
  return true;
}

bool GetBoolean(const toml::table& t, const char* key, bool* out, const std::string& source,
                std::string* error);

// [free]: the free pose source's coverage, field and samples in motion.
bool ParseFree(const toml::table* t, const std::string& source, StationOptions* out,
               std::string* error) {
  StationOptions& st = *out;
  if (!OnlyKeys(
          *t, {"min_coverage_percent", "field", "motion", "max_motion_points", "mag_bandwidth_hz"},
          "[free]", source, error) ||
      !GetNumber(*t, "min_coverage_percent", &st.free.min_coverage_percent, source, error) ||
      !GetNumber(*t, "mag_bandwidth_hz", &st.free.mag_bandwidth_hz, source, error) ||
      !GetBoolean(*t, "motion", &st.free.motion, source, error) ||
      !GetInt(*t, "max_motion_points", &st.free.max_motion_points, source, error)) {
    return false;
  }
  std::string field = "reference";
  if (!GetString(*t, "field", &field, source, error)) return false;
  if (field != "reference" && field != "unknown") {
    *error = fmt::format("{}: [free] field must be \"reference\" or \"unknown\"", source);
    return false;
  }
  st.free.field_known = field == "reference";
  return true;
}

// A boolean key, if present (as_boolean: value<bool>() would take 1 for true).
bool GetBoolean(const toml::table& t, const char* key, bool* out, const std::string& source,
                std::string* error) {
  const toml::node* n = t.get(key);
  if (!n) return true;
  const auto* v = n->as_boolean();
  if (!v) {
    *error = fmt::format("{}: '{}' must be true or false", Where(*n, source), key);
    return false;
  }
  *out = v->get();
  return true;
}

// [thermal]: calibrations over temperature ("MODEL@T" in the models; docs/THERMAL.md).
bool ParseThermal(const toml::table* t, const std::string& source, StationOptions* out,
                  std::string* error) {
  ThermalStationOptions& th = out->thermal;
  return OnlyKeys(*t,
                  {"max_order", "t0_c", "drop_below_sigmas", "distinct_resolution_c", "min_span_c",
                   "grid_points", "soak_rate_c_per_min", "soak_window_s", "soak_timeout_s",
                   "max_pose_span_c", "soak_check_bias"},
                  "[thermal]", source, error) &&
         GetBoolean(*t, "soak_check_bias", &th.soak.check_bias, source, error) &&
         GetInt(*t, "max_order", &th.fit.max_order, source, error) &&
         GetNumber(*t, "t0_c", &th.fit.t0_c, source, error) &&
         GetNumber(*t, "drop_below_sigmas", &th.fit.drop_below_sigmas, source, error) &&
         GetNumber(*t, "distinct_resolution_c", &th.fit.distinct_resolution_c, source, error) &&
         GetNumber(*t, "min_span_c", &th.gate.min_span_c, source, error) &&
         GetInt(*t, "grid_points", &th.gate.grid_points, source, error) &&
         GetNumber(*t, "soak_rate_c_per_min", &th.soak.max_rate_c_per_min, source, error) &&
         GetNumber(*t, "soak_window_s", &th.soak.window_s, source, error) &&
         GetNumber(*t, "soak_timeout_s", &th.soak.timeout_s, source, error) &&
         GetNumber(*t, "max_pose_span_c", &th.max_pose_span_c, source, error);
}

// [reference]: gravity, the field and the latitude.
bool ParseReference(const toml::table* t, const std::string& source, StationOptions* out,
                    std::string* error) {
  StationOptions& st = *out;
  if (!OnlyKeys(*t, {"g_ned", "B_ned", "latitude_deg"}, "[reference]", source, error) ||
      !GetVector(*t, "g_ned", &st.context.reference.g_ned, source, error) ||
      !GetVector(*t, "B_ned", &st.context.reference.B_ned, source, error) ||
      !GetNumber(*t, "latitude_deg", &st.context.reference.latitude_deg, source, error)) {
    return false;
  }
  if (std::string why; !st.context.reference.IsValid(&why)) {
    *error = fmt::format("{}: [reference]: {}", source, why);
    return false;
  }
  return true;
}

// One [[device]]: its spec, settings, and its own models and gate tolerances.
bool ParseDevice(const toml::node& d, const toml::table* t, const std::string& source, Config* out,
                 std::vector<std::string>* slots_taken, std::string* error) {
  Config& c = *out;
  StationOptions& st = c.station;
  if (!OnlyKeys(*t,
                {"name", "protocol", "port", "baud", "rate_hz", "configure", "models", "gate",
                 "slot", "mount"},
                "[[device]]", source, error)) {
    return false;
  }
  DeviceSettings settings;
  if (!GetNumber(*t, "rate_hz", &settings.rate_hz, source, error)) return false;
  if (const toml::node* cn = t->get("configure")) {
    const auto* v = cn->as_boolean();  // value<bool>() would take 1 for true
    if (!v) {
      *error = fmt::format("{}: 'configure' must be true or false", Where(*cn, source));
      return false;
    }
    settings.configure = v->get();
  }
  if (t->get("rate_hz") && !(settings.rate_hz > 0 && settings.rate_hz <= 4000)) {
    *error = fmt::format("{}: 'rate_hz' must be in (0, 4000]", Where(d, source));
    return false;
  }
  std::string name, protocol, port;
  double baud = 0;
  if (!GetString(*t, "name", &name, source, error) ||
      !GetString(*t, "protocol", &protocol, source, error) ||
      !GetString(*t, "port", &port, source, error) ||
      !GetNumber(*t, "baud", &baud, source, error)) {
    return false;
  }
  if (!drivers::ParseProtocol(protocol)) {
    *error = fmt::format("{}: device: unknown protocol '{}' (mip, gx2, xbus, xbus-legacy)",
                         Where(d, source), protocol);
    return false;
  }
  if (const toml::node* bn = t->get("baud")) {
    // As on the command line (drivers/device_spec.h); never a silent default.
    if (!(baud >= 300 && baud <= 4000000 && baud == std::floor(baud))) {
      *error =
          fmt::format("{}: 'baud' must be a whole number from 300 to 4000000", Where(*bn, source));
      return false;
    }
  } else {
    baud = drivers::DeviceSpec().baud;
  }
  // The baud always given: an '@' in the port stays in the port.
  const std::string spec =
      fmt::format("{}={}:{}@{}", name, protocol, port, static_cast<long long>(baud));
  std::string why;
  auto parsed = drivers::ParseDeviceSpec(spec, &why);
  if (!parsed) {
    *error = fmt::format("{}: device: {}", Where(d, source), why);
    return false;
  }
  for (const auto& other : c.devices) {
    if (other.name == parsed->name) {
      *error = fmt::format("{}: device name '{}' is given twice", Where(d, source), name);
      return false;
    }
  }
  c.devices.push_back(*parsed);
  c.device_settings[parsed->name] = settings;
  // The device's own models and gate tolerances (over the station's).
  DeviceModelOptions own;
  if (t->get("models")) {
    std::vector<std::string> models;
    if (!GetModels(*t, &models, source, error)) return false;
    own.models = models;
  }
  if (const toml::table* g = (*t)["gate"].as_table()) {
    GateOptions gate = st.gate;  // tolerances so far: the class's or [gate]'s
    if (!ParseGate(*g, "[device.gate]", source, &gate, error)) return false;
    own.gate = gate;
  }
  if (!ParseDeviceMount(*t, parsed->name, c.fixture, source, slots_taken, &own, error)) {
    return false;
  }
  if (own.models || own.gate || own.mount) st.per_device[parsed->name] = own;
  return true;
}

// Every [[device]].
bool ParseDevices(const toml::node* n, const std::string& source, Config* out, std::string* error) {
  const toml::array* a = n->as_array();
  if (!a) {
    *error = fmt::format("{}: devices are [[device]] tables", Where(*n, source));
    return false;
  }
  std::vector<std::string> slots_taken;  // a slot holds one unit
  for (const auto& d : *a) {
    const toml::table* t = d.as_table();
    if (!t) {
      *error = fmt::format("{}: devices are [[device]] tables", Where(d, source));
      return false;
    }
    if (!ParseDevice(d, t, source, out, &slots_taken, error)) return false;
  }
  return true;
}

// The top level's keys: the socket, its group, who may control, the state directory.
bool ParseTopLevel(const toml::table& root, const std::string& source, Config* out,
                   std::string* error) {
  Config& c = *out;
  std::string s;
  if (root.get("socket")) {
    if (!GetString(root, "socket", &s, source, error)) return false;
    c.socket_path = s;
  }
  if (root.get("socket_group")) {
    if (!GetString(root, "socket_group", &s, source, error)) return false;
    c.socket_group = s;
  }
  if (const toml::node* n = root.get("control_users")) {
    const toml::array* a = n->as_array();
    if (!a) {
      *error = fmt::format("{}: 'control_users' must be an array of user names or uids",
                           Where(*n, source));
      return false;
    }
    for (const auto& u : *a) {
      std::string name;
      if (auto v = u.value<std::string>()) {
        name = *v;
      } else if (const auto* i = u.as_integer(); i && i->get() >= 0) {
        // An integer node only: value<std::int64_t>() would convert a float (1e301: undefined).
        name = std::to_string(i->get());
      } else {
        *error = fmt::format("{}: 'control_users' holds user names or uids", Where(u, source));
        return false;
      }
      unsigned uid = 0;
      std::string why;
      if (!ResolveUser(name, &uid, &why)) {
        *error = fmt::format("{}: control_users: {}", Where(u, source), why);
        return false;
      }
      c.control_uids.push_back(uid);
    }
  }
  if (root.get("state_dir")) {
    if (!GetString(root, "state_dir", &s, source, error)) return false;
    c.state_dir = s;
  }
  return true;
}

}  // namespace

bool ParseConfig(const std::string& text, const std::string& source, Config* out,
                 std::string* error) {
  toml::table root;
  try {
    root = toml::parse(text, source);
  } catch (const toml::parse_error& e) {
    *error = fmt::format("{}:{}: {}", source, e.source().begin.line, e.description());
    return false;
  }
  Config c;
  if (!OnlyKeys(root,
                {"socket", "socket_group", "control_users", "state_dir", "station", "sequencer",
                 "table", "free", "thermal", "gate", "reference", "device", "registry", "fixture"},
                "the file", source, error) ||
      !ParseTopLevel(root, source, &c, error)) {
    return false;
  }
  StationOptions& st = c.station;
  if (const toml::table* t = root["station"].as_table(); t && !ParseStation(t, source, &c, error)) {
    return false;
  }
  if (const toml::table* t = root["sequencer"].as_table();
      t && !ParseSequencer(t, source, &c, error)) {
    return false;
  }
  if (const toml::table* t = root["table"].as_table(); t && !ParseTable(*t, source, &st, error)) {
    return false;
  }
  if (const toml::table* t = root["free"].as_table(); t && !ParseFree(t, source, &st, error)) {
    return false;
  }
  if (const toml::table* t = root["thermal"].as_table();
      t && !ParseThermal(t, source, &st, error)) {
    return false;
  }
  if (st.pose_source == PoseSource::kFree) ApplyPoseSource(PoseSource::kFree, c, &st);
  GateDefaultsForClass(st.sensor_class, &st.gate);
  if (const toml::table* t = root["gate"].as_table()) {
    if (!ParseGate(*t, "[gate]", source, &st.gate, error)) return false;
    st.gate_tolerances_set = true;
  }
  if (const toml::table* t = root["reference"].as_table();
      t && !ParseReference(t, source, &st, error)) {
    return false;
  }
  if (const toml::table* t = root["registry"].as_table();
      t && !ParseRegistry(*t, source, &c.registry, error)) {
    return false;
  }
  if (const toml::table* t = root["fixture"].as_table()) {
    if (!ParseFixture(*t, source, &c.fixture, error)) return false;
    st.fixture = c.fixture.name;
    st.batch_id = c.fixture.batch;
  } else if (const toml::node* f = root.get("fixture")) {
    *error =
        fmt::format("{}: [fixture] is a table (name, file or [[fixture.slot]])", Where(*f, source));
    return false;
  }
  if (const toml::node* n = root.get("device"); n && !ParseDevices(n, source, &c, error)) {
    return false;
  }
  if (!st.IsValid(error)) {
    *error = source + ": " + *error;
    return false;
  }
  *out = std::move(c);
  return true;
}

bool LoadConfig(const std::string& path, Config* out, std::string* error) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    *error = "cannot open configuration '" + path + "'";
    return false;
  }
  std::stringstream text;
  text << in.rdbuf();
  return ParseConfig(text.str(), path, out, error);
}

void ApplyPoseSource(PoseSource source, const Config& config, StationOptions* station) {
  station->pose_source = source;
  if (source != PoseSource::kFree) return;
  if (!config.models_set) station->models.clear();
  if (!config.dwell_set) station->sequencer.dwell_s = kFreeDwellS;
}

}  // namespace turncal::daemon
