#include "protocol/free_json.h"

#include <fmt/format.h>

#include <cmath>

#include "protocol/calibration_json.h"
#include "protocol/sequencer_json.h"
#include "turncal/version.h"

namespace turncal::protocol {
namespace {

nlohmann::json Number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); }

nlohmann::json Figures(const std::vector<MisfitFigure>& figures) {
  nlohmann::json j = nlohmann::json::array();
  for (const auto& f : figures) {
    j.push_back({{"kind", f.kind}, {"count", f.count}, {"rms", f.rms}, {"max", f.max_abs}});
  }
  return j;
}

bool ReadFinite(const nlohmann::json& j, const char* key, double* out) {
  if (!j.contains(key)) return true;
  if (!j[key].is_number() || !std::isfinite(j[key].get<double>())) return false;
  *out = j[key].get<double>();
  return true;
}

nlohmann::json TolerancesJson(const GateTolerances& t) {
  return {{"scale_factor", t.scale_factor},
          {"angle_rad", t.angle_rad},
          {"acceleration_mps2", t.acceleration_mps2},
          {"gain", t.gain},
          {"field", t.field},
          {"angular_rate_radps", t.angular_rate_radps},
          {"g_sensitivity", t.g_sensitivity}};
}

bool ReadTolerances(const nlohmann::json& j, GateTolerances* t) {
  if (!j.is_object()) return false;
  return ReadFinite(j, "scale_factor", &t->scale_factor) &&
         ReadFinite(j, "angle_rad", &t->angle_rad) &&
         ReadFinite(j, "acceleration_mps2", &t->acceleration_mps2) &&
         ReadFinite(j, "gain", &t->gain) && ReadFinite(j, "field", &t->field) &&
         ReadFinite(j, "angular_rate_radps", &t->angular_rate_radps) &&
         ReadFinite(j, "g_sensitivity", &t->g_sensitivity);
}

// The triads a free model (and the model it builds on) reads from an interval.
PoseRecord Evidence(const FreeModel& model, const FreeModel* upstream, const PoseRecord& r) {
  auto needs = [&](SensorKind k) { return model.Needs(k) || (upstream && upstream->Needs(k)); };
  PoseRecord out = r;
  if (!needs(SensorKind::kAccelerometer)) out.acc.reset();
  if (!needs(SensorKind::kGyroscope)) {
    out.gyr.reset();
    out.move_in.reset();
  }
  if (!needs(SensorKind::kMagnetometer)) out.mag.reset();
  return out;
}

}  // namespace

nlohmann::json ToJson(const FreeContext& c) {
  return {{"gravity_mps2", c.gravity_mps2},
          {"field_magnitude", c.field_magnitude},
          {"earth_rate_radps", c.earth_rate_radps},
          {"latitude_deg", c.latitude_deg},
          {"dip_deg", c.dip_deg},
          {"acc_offset_sigma", c.acc_offset_sigma},
          {"mag_offset_sigma", c.mag_offset_sigma},
          {"gyr_offset_sigma", c.gyr_offset_sigma},
          {"acc_drift", ToJson(c.acc_drift)},
          {"mag_drift", ToJson(c.mag_drift)},
          {"gyr_drift", ToJson(c.gyr_drift)}};
}

bool ParseFreeContext(const nlohmann::json& j, FreeContext* out, std::string* error) {
  if (!j.is_object()) {
    *error = "\"context\" must be an object";
    return false;
  }
  const std::pair<const char*, double*> numbers[] = {{"gravity_mps2", &out->gravity_mps2},
                                                     {"field_magnitude", &out->field_magnitude},
                                                     {"earth_rate_radps", &out->earth_rate_radps},
                                                     {"latitude_deg", &out->latitude_deg},
                                                     {"dip_deg", &out->dip_deg},
                                                     {"acc_offset_sigma", &out->acc_offset_sigma},
                                                     {"mag_offset_sigma", &out->mag_offset_sigma},
                                                     {"gyr_offset_sigma", &out->gyr_offset_sigma}};
  for (const auto& [key, target] : numbers) {
    if (!ReadFinite(j, key, target)) {
      *error = fmt::format("context.{} must be a finite number", key);
      return false;
    }
  }
  for (auto [key, drift] : {std::pair{"acc_drift", &out->acc_drift},
                            {"mag_drift", &out->mag_drift},
                            {"gyr_drift", &out->gyr_drift}}) {
    if (j.contains(key) && !ParseBiasDrift(j[key], drift)) {
      *error = fmt::format("context.{} is not a drift model", key);
      return false;
    }
  }
  return out->IsValid(error);
}

nlohmann::json ToJson(const CoverageGap& gap) {
  return {{"direction", {gap.direction.x(), gap.direction.y(), gap.direction.z()}},
          {"name", CaseDirectionName(gap.direction)},
          {"radius_deg", gap.radius_deg},
          {"empty_area_fraction", gap.empty_area_fraction}};
}

nlohmann::json FreeGateJson(const FreeCalibratorOptions& o) {
  nlohmann::json precision;
  if (o.precision) {
    nlohmann::json parameters = nlohmann::json::object();
    for (const auto& [name, v] : o.precision->parameter_tolerance) parameters[name] = v;
    precision = {{"min_dof", o.precision->min_dof},
                 {"min_p_value", o.precision->min_p_value},
                 {"tolerances", TolerancesJson(o.precision->tolerances)},
                 {"parameters", parameters}};
  }
  return {{"min_coverage", o.min_coverage},
          {"min_relative_singular", o.min_relative_singular},
          {"precision", precision}};
}

bool ParseFreeGate(const nlohmann::json& j, FreeCalibratorOptions* out, std::string* error) {
  auto fail = [&](const char* what) {
    *error = fmt::format("free_gate: {}", what);
    return false;
  };
  if (!j.is_object()) return fail("must be an object");
  if (!ReadFinite(j, "min_coverage", &out->min_coverage) ||
      !ReadFinite(j, "min_relative_singular", &out->min_relative_singular)) {
    return fail("min_coverage and min_relative_singular must be finite numbers");
  }
  out->precision.reset();
  if (j.contains("precision") && !j["precision"].is_null()) {
    const auto& p = j["precision"];
    GateOptions g;
    double min_dof = g.min_dof;
    if (!p.is_object() || !ReadFinite(p, "min_dof", &min_dof) ||
        !ReadFinite(p, "min_p_value", &g.min_p_value) ||
        (p.contains("tolerances") && !ReadTolerances(p["tolerances"], &g.tolerances))) {
      return fail("precision must hold min_dof, min_p_value and tolerances as numbers");
    }
    g.min_dof = static_cast<int>(min_dof);
    if (p.contains("parameters")) {
      if (!p["parameters"].is_object()) return fail("precision.parameters must be an object");
      for (const auto& [name, v] : p["parameters"].items()) {
        if (!v.is_number()) return fail("precision.parameters must hold numbers");
        g.parameter_tolerance[name] = v.get<double>();
      }
    }
    if (!g.IsValid(error)) return false;
    out->precision = g;
  }
  return out->IsValid(error);
}

nlohmann::json FreeResultJson(const FreeModelResult& r,
                              const std::optional<OrientationAdvice>& advice) {
  const FreeEstimate& fe = r.estimate;
  const Estimate& e = fe.estimate;
  nlohmann::json m = {{"requested", r.requested},
                      {"model", r.model},
                      {"note", r.note},
                      {"ok", e.ok},
                      {"intervals", fe.intervals}};
  if (fe.motion_points > 0) m["motion_points"] = fe.motion_points;
  nlohmann::json params = nlohmann::json::object();
  const bool values = e.ok && e.theta.size() == static_cast<Eigen::Index>(e.parameters.size()) &&
                      e.sigma.size() == e.theta.size();
  for (std::size_t p = 0; values && p < e.parameters.size(); ++p) {
    const auto k = static_cast<Eigen::Index>(p);
    params[e.parameters[p].name] = {{"value", e.theta[k]}, {"sigma", Number(e.sigma[k])}};
  }
  m["params"] = params;
  // A model not fitted yet (no interval) has no error of its own.
  const std::string why = e.error.empty() ? "no static interval fitted yet" : e.error;
  m["gate"] = {
      {"pass", e.ok && fe.gate_passed},
      {"reasons", e.ok ? fe.gate_reasons : std::vector<std::string>{"no estimate: " + why}}};
  if (!e.ok) {
    m["error"] = why;
    m["rank"] = 0;
    return m;
  }
  m["residuals"] = fe.residuals;
  m["rank"] = e.rank;
  m["condition"] = Number(e.condition);
  m["chi2"] = e.chi2;
  m["dof"] = e.dof;
  m["p_value"] = e.p_value;
  m["covariance_scale"] = e.covariance_scale;
  m["fit_check"] = {{"verdict", ToString(e.fit.verdict)}, {"cause", e.fit.cause}};
  if (std::isfinite(e.fit.noise_dof)) {
    m["fit_check"]["noise_dof"] = e.fit.noise_dof;
    m["fit_check"]["noise_scale"] = e.fit.noise_scale;
  }
  if (e.fit.dof_share < 1) m["fit_check"]["dof_share"] = e.fit.dof_share;
  m["coverage"] = {{"filled", fe.coverage.filled},
                   {"total", fe.coverage.total},
                   {"fraction", fe.coverage.fraction()}};
  if (!fe.gap.empty()) m["coverage"]["gap"] = ToJson(fe.gap);
  m["weak"] = fe.weak;
  m["undetermined"] = fe.undetermined;
  m["weakest_direction"] = fe.analysis.weak.empty() ? "" : fe.analysis.weak.back().text;
  m["misfit_before"] = Figures(fe.before);
  m["misfit_after"] = Figures(fe.after);
  m["relative_scale"] = fe.relative_scale;
  m["bias_window"] = fe.bias_window_host ? ToJson(*fe.bias_window_host) : nlohmann::json();
  m["warnings"] = e.warnings;
  if (fe.field_wander > 0) m["field_wander"] = fe.field_wander;
  if (fe.correlation.pairs > 0) {
    const MotionCorrelation& c = fe.correlation;
    m["correlation"] = {
        {"pairs", c.pairs},         {"lag_one", c.lag_one},     {"lag_one_raw", c.lag_one_raw},
        {"threshold", c.threshold}, {"spacing_s", c.spacing_s}, {"tau_s", c.tau_s},
        {"whitened", c.whitened}};
  }
  if (fe.norm_bias.size() == static_cast<Eigen::Index>(e.parameters.size())) {
    nlohmann::json bias = nlohmann::json::object();
    for (std::size_t i = 0; i < e.parameters.size(); ++i) {
      bias[e.parameters[i].name] = fe.norm_bias[static_cast<Eigen::Index>(i)];
    }
    m["norm_bias"] = bias;  // removed from the values above (core/estimation/free_bias.h)
    m["norm_bias_sigmas"] = fe.norm_bias_sigmas;  // its size in the estimate's own metric
  }
  if (fe.disturbance) {
    const FieldDisturbance& d = *fe.disturbance;
    m["disturbed"] = {{"values", d.values},
                      {"detected", d.detected},
                      {"of", d.of},
                      {"t0_s", d.t0_s},
                      {"t1_s", d.t1_s},
                      {"largest_percent", d.largest_percent},
                      {"largest_sigmas", d.largest_sigmas}};
  }
  if (advice) m["advice"] = {{"text", advice->text}, {"sigma_ratio", advice->sigma_ratio}};
  return m;
}

nlohmann::json FreeCalibrationJson(const FreeCalibrationInput& in) {
  const FreeModelResult& r = *in.result;
  const Estimate& e = r.estimate.estimate;
  nlohmann::json j = FreeResultJson(r, in.advice);
  nlohmann::json order = nlohmann::json::array();
  for (const auto& p : e.parameters) order.push_back(p.name);
  nlohmann::json covariance = nlohmann::json::array();
  for (Eigen::Index a = 0; a < e.covariance.rows(); ++a) {
    nlohmann::json row = nlohmann::json::array();
    for (Eigen::Index b = 0; b < e.covariance.cols(); ++b)
      row.push_back(Number(e.covariance(a, b)));
    covariance.push_back(row);
  }
  std::string error;
  auto model = MakeFreeModel(r.model, in.context, &error);
  auto upstream = in.upstream ? MakeFreeModel(in.upstream->model, in.context, &error) : nullptr;
  nlohmann::json records = nlohmann::json::array();
  for (const auto& iv : in.intervals) {
    records.push_back(ToJson(model ? Evidence(*model, upstream.get(), iv) : iv));
  }
  nlohmann::json up;
  if (in.upstream && in.upstream->estimate.estimate.ok) {
    const Eigen::VectorXd& t = in.upstream->estimate.estimate.theta;
    up = {{"model", in.upstream->model},
          {"theta", std::vector<double>(t.data(), t.data() + t.size())}};
  }
  j["schema"] = 1;
  j["class"] = "CALIBRATION";
  j["pose_source"] = "free";
  j["device"] = in.device;
  j["version"] = in.version;
  j["software"] = kVersion;
  j["parameter_order"] = order;
  j["covariance"] = covariance;
  j["upstream"] = up;
  j["context"] = ToJson(in.context);
  j["free_gate"] = FreeGateJson(in.options);
  j["sensor_class"] = in.sensor_class;
  j["provenance"] = {{"records", records}, {"device_identity", in.identity}};
  return j;
}

bool IsFreeCalibration(const nlohmann::json& j) {
  return j.is_object() && j.contains("pose_source") && j["pose_source"] == "free";
}

bool ParseFreeCalibration(const nlohmann::json& j, FreeCalibrationDocument* out,
                          std::string* error) {
  auto fail = [&](const std::string& why) {
    *error = why;
    return false;
  };
  if (!IsFreeCalibration(j)) return fail("not a free calibration (no \"pose_source\": \"free\")");
  for (const char* key : {"device", "model", "requested"}) {
    if (!j.contains(key) || !j[key].is_string())
      return fail(fmt::format("\"{}\" must be a string", key));
  }
  if (!j.contains("version") || !j["version"].is_number_integer()) {
    return fail("\"version\" must be a whole number");
  }
  *out = FreeCalibrationDocument{};
  out->device = j["device"].get<std::string>();
  out->model = j["model"].get<std::string>();
  out->requested = j["requested"].get<std::string>();
  out->version = j["version"].get<int>();
  out->software = j.value("software", "");
  out->time = j.value("time", "");
  if (j.contains("context") && !ParseFreeContext(j["context"], &out->context, error)) return false;
  if (j.contains("free_gate") && !ParseFreeGate(j["free_gate"], &out->options, error)) {
    return false;
  }
  auto model = MakeFreeModel(out->model, out->context, error);
  if (!model) return false;
  const auto& params = model->parameters();
  const auto n = static_cast<Eigen::Index>(params.size());
  out->theta.resize(n);
  if (!j.contains("params") || !j["params"].is_object())
    return fail("\"params\" must be an object");
  for (Eigen::Index k = 0; k < n; ++k) {
    const std::string& name = params[static_cast<std::size_t>(k)].name;
    const auto it = j["params"].find(name);
    if (it == j["params"].end() || !it->is_object() || !(*it).contains("value") ||
        !(*it)["value"].is_number() || !std::isfinite((*it)["value"].get<double>())) {
      return fail(fmt::format("params.{} has no finite value", name));
    }
    out->theta[k] = (*it)["value"].get<double>();
  }
  if (j.contains("covariance") && j["covariance"].is_array() &&
      j["covariance"].size() == params.size()) {
    Eigen::MatrixXd c(n, n);
    bool good = true;
    for (Eigen::Index a = 0; good && a < n; ++a) {
      const auto& row = j["covariance"][static_cast<std::size_t>(a)];
      good = row.is_array() && row.size() == params.size();
      for (Eigen::Index b = 0; good && b < n; ++b) {
        good = row[static_cast<std::size_t>(b)].is_number();
        if (good) c(a, b) = row[static_cast<std::size_t>(b)].get<double>();
      }
    }
    if (good && c.allFinite()) out->covariance = c;
  }
  if (j.contains("upstream") && j["upstream"].is_object()) {
    const auto& u = j["upstream"];
    if (!u.contains("model") || !u["model"].is_string() || !u.contains("theta") ||
        !u["theta"].is_array()) {
      return fail("\"upstream\" must hold \"model\" and \"theta\"");
    }
    out->upstream_model = u["model"].get<std::string>();
    auto up = MakeFreeModel(out->upstream_model, out->context, error);
    if (!up) return false;
    if (u["theta"].size() != static_cast<std::size_t>(up->num_parameters())) {
      return fail("upstream.theta does not fit its model");
    }
    out->upstream_theta.resize(up->num_parameters());
    for (int k = 0; k < up->num_parameters(); ++k) {
      const auto& v = u["theta"][static_cast<std::size_t>(k)];
      if (!v.is_number()) return fail("upstream.theta must hold numbers");
      out->upstream_theta[k] = v.get<double>();
    }
  }
  TimeWindow w;
  if (j.contains("bias_window") && ParseTimeWindow(j["bias_window"], &w)) out->bias_window = w;
  if (j.contains("provenance") && j["provenance"].is_object()) {
    const auto& p = j["provenance"];
    out->identity = p.value("device_identity", nlohmann::json());
    if (p.contains("records")) {
      if (!p["records"].is_array()) return fail("provenance.records must be an array");
      for (const auto& rj : p["records"]) {
        PoseRecord record;
        std::string why;
        if (!ParsePoseRecord(rj, &record, &why)) {
          return fail(fmt::format("provenance.records[{}]: {}", out->intervals.size(), why));
        }
        out->intervals.push_back(std::move(record));
      }
    }
  }
  out->override_who = j.value("override", nlohmann::json());
  return true;
}

}  // namespace turncal::protocol
