#include "protocol/calibration_json.h"

#include <fmt/format.h>

#include <cmath>

#include "core/estimation/sensor_class.h"
#include "core/frames/units.h"
#include "protocol/json_vec3.h"
#include "protocol/pose_json.h"
#include "protocol/sequencer_json.h"

namespace turncal::protocol {
namespace {

// A number, or NaN for null (an undetermined sigma or covariance entry).
bool ReadNumberOrNull(const nlohmann::json& j, double* v) {
  if (j.is_null()) {
    *v = std::nan("");
    return true;
  }
  if (!j.is_number()) return false;
  *v = j.get<double>();
  return true;
}

bool ReadStrings(const nlohmann::json& j, std::vector<std::string>* out) {
  if (!j.is_array()) return false;
  out->clear();
  for (const auto& s : j) {
    if (!s.is_string()) return false;
    out->push_back(s.get<std::string>());
  }
  return true;
}

bool ReadGate(const nlohmann::json& j, GateResult* gate) {
  if (!j.is_object() || !j.contains("pass") || !j["pass"].is_boolean()) return false;
  gate->pass = j["pass"].get<bool>();
  const std::pair<const char*, std::vector<std::string>*> lists[] = {
      {"reasons", &gate->reasons}, {"missing", &gate->missing}, {"notes", &gate->notes}};
  for (const auto& [key, list] : lists) {
    if (j.contains(key) && !ReadStrings(j[key], list)) return false;
  }
  return true;
}

bool ReadCalibrator(const nlohmann::json& j, CalibratorOptions* o, std::string* sensor_class) {
  if (!j.is_object()) return false;
  for (const char* key : {"noise_density", "pose_offset_sigma", "loss_scale"}) {
    if (j.contains(key) && (!j[key].is_number() || !std::isfinite(j[key].get<double>()))) {
      return false;
    }
  }
  o->noise_density = j.value("noise_density", o->noise_density);
  o->pose_offset_sigma = j.value("pose_offset_sigma", o->pose_offset_sigma);
  o->loss_scale = j.value("loss_scale", o->loss_scale);
  if (j.contains("loss")) {
    if (!j["loss"].is_string()) return false;
    const std::string loss = j["loss"].get<std::string>();
    bool known = false;
    for (RobustLoss l : {RobustLoss::kNone, RobustLoss::kHuber, RobustLoss::kCauchy}) {
      if (loss == ToString(l)) {
        o->loss = l;
        known = true;
      }
    }
    if (!known) return false;
  }
  if (j.contains("sensor_class")) {
    if (!j["sensor_class"].is_string()) return false;
    *sensor_class = j["sensor_class"].get<std::string>();
  }
  // Documents written before the drift model have none: they were solved without one.
  if (j.contains("drift") && !ParseBiasDrift(j["drift"], &o->drift)) return false;
  return o->IsValid(nullptr);
}

}  // namespace

nlohmann::json ToJson(const ModelContext& c) {
  nlohmann::json mounting = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) mounting.push_back(JsonVec3(c.mounting.row(r).transpose()));
  return {{"g_ned", JsonVec3(c.reference.g_ned)},
          {"B_ned", JsonVec3(c.reference.B_ned)},
          {"mounting", mounting},
          {"accel_output_frame", turncal::ToString(c.accel_output_frame)}};
}

bool ParseModelContext(const nlohmann::json& j, ModelContext* out, std::string* error) {
  auto fail = [&](const std::string& what) {
    if (error) *error = "context: " + what;
    return false;
  };
  if (!j.is_object()) return fail("not an object");
  ModelContext c = *out;
  if (j.contains("g_ned") && !ReadJsonVec3(j["g_ned"], &c.reference.g_ned)) {
    return fail("g_ned must be 3 finite numbers");
  }
  if (j.contains("B_ned") && !ReadJsonVec3(j["B_ned"], &c.reference.B_ned)) {
    return fail("B_ned must be 3 finite numbers");
  }
  if (j.contains("mounting")) {
    const auto& m = j["mounting"];
    if (!m.is_array() || m.size() != 3) return fail("mounting must be 3 rows of 3 numbers");
    for (std::size_t r = 0; r < 3; ++r) {
      Eigen::Vector3d row;
      if (!ReadJsonVec3(m[r], &row)) return fail("mounting must be 3 rows of 3 numbers");
      c.mounting.row(static_cast<Eigen::Index>(r)) = row.transpose();
    }
  }
  if (j.contains("accel_output_frame")) {
    const auto& f = j["accel_output_frame"];
    if (f == turncal::ToString(OutputFrame::kCase)) {
      c.accel_output_frame = OutputFrame::kCase;
    } else if (f == turncal::ToString(OutputFrame::kTable)) {
      c.accel_output_frame = OutputFrame::kTable;
    } else {
      return fail("accel_output_frame must be \"case\" or \"table\"");
    }
  }
  std::string why;
  if (!c.IsValid(&why)) return fail(why);
  *out = c;
  return true;
}

nlohmann::json CalibratorJson(const CalibratorOptions& o, const std::string& sensor_class) {
  nlohmann::json j = {{"sensor_class", sensor_class},
                      {"noise_density", o.noise_density},
                      {"pose_offset_sigma", o.pose_offset_sigma},
                      {"loss", ToString(o.loss)},
                      {"loss_scale", o.loss_scale}};
  if (o.drift.enabled()) j["drift"] = ToJson(o.drift);
  return j;
}

nlohmann::json ToJson(const FitCheck& f, SensorKind sensor) {
  return {{"verdict", ToString(f.verdict)},
          {"chi2_per_dof", f.dof > 0 ? f.chi2 / f.dof : 0.0},
          {"p_upper", f.p_upper},
          {"p_lower", f.p_lower},
          {"axis_ratio", JsonVec3(f.axis_ratio)},
          {"lag1_correlation", f.lag1_correlation},
          {"cause", f.cause},
          {"message", f.Message(ToString(sensor))}};
}

nlohmann::json ToJson(const BiasDrift& d) {
  nlohmann::json j = {{"gauss_markov_sigma", JsonVec3(d.gm_sigma)},
                      {"gauss_markov_tau_s", d.gm_tau_s},
                      {"random_walk", JsonVec3(d.rw_density)},
                      {"warmup_sigma", JsonVec3(d.warmup_sigma)},
                      {"warmup_tau_s", d.warmup_tau_s}};
  if (std::isfinite(d.warmup_origin_s)) j["warmup_origin_s"] = d.warmup_origin_s;
  return j;
}

nlohmann::json ToJson(const DriftScale& d) {
  auto finite = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); };
  nlohmann::json j;
  j["identified"] = d.identified;
  j["scale"] = d.scale;
  j["log_sigma"] = finite(d.log_sigma);
  j["data_scale"] = d.data_scale;
  j["data_log_sigma"] = finite(d.data_log_sigma);
  j["prior_log_sigma"] = d.prior_log_sigma;
  j["rejects_prior"] = d.rejects_prior;
  j["use_scale"] = d.use_scale;
  return j;
}

bool ParseBiasDrift(const nlohmann::json& j, BiasDrift* out) {
  if (!j.is_object()) return false;
  BiasDrift d;
  if (j.contains("gauss_markov_sigma") && !ReadJsonVec3(j["gauss_markov_sigma"], &d.gm_sigma)) {
    return false;
  }
  if (j.contains("random_walk") && !ReadJsonVec3(j["random_walk"], &d.rw_density)) return false;
  if (j.contains("warmup_sigma") && !ReadJsonVec3(j["warmup_sigma"], &d.warmup_sigma)) {
    return false;
  }
  for (const auto& [key, target] :
       {std::pair<const char*, double*>{"gauss_markov_tau_s", &d.gm_tau_s},
        {"warmup_tau_s", &d.warmup_tau_s},
        {"warmup_origin_s", &d.warmup_origin_s}}) {
    if (!j.contains(key)) continue;
    if (!j[key].is_number()) return false;
    *target = j[key].get<double>();
  }
  if (!d.IsValid(nullptr)) return false;
  *out = d;
  return true;
}

nlohmann::json ToJson(const TimeWindow& w) { return {{"t0_s", w.t0_s}, {"t1_s", w.t1_s}}; }

bool ParseTimeWindow(const nlohmann::json& j, TimeWindow* out) {
  if (!j.is_object() || !j.contains("t0_s") || !j.contains("t1_s") || !j["t0_s"].is_number() ||
      !j["t1_s"].is_number()) {
    return false;
  }
  const TimeWindow w{j["t0_s"].get<double>(), j["t1_s"].get<double>()};
  if (!std::isfinite(w.t0_s) || !std::isfinite(w.t1_s) || !(w.t1_s > w.t0_s)) return false;
  *out = w;
  return true;
}

nlohmann::json TolerancesJson(const MeasurementModel& model, const GateOptions& gate) {
  nlohmann::json out = nlohmann::json::object();
  for (int i : GatedParameters(model)) {
    const ParameterInfo& p = model.parameters()[static_cast<std::size_t>(i)];
    out[p.name] = ToleranceFor(p, gate);
  }
  return out;
}

namespace {

bool Why(std::string* why, const std::string& what) {
  *why = what;
  return false;
}

// "parameter_order", "params" and "covariance" in the model's order.
bool ReadParameters(const nlohmann::json& j, const MeasurementModel& model, CalibrationDocument* d,
                    std::string* why) {
  const auto& params = model.parameters();
  const auto n = static_cast<Eigen::Index>(params.size());
  if (j.contains("parameter_order")) {
    std::vector<std::string> order;
    if (!ReadStrings(j["parameter_order"], &order)) return Why(why, "parameter_order is malformed");
    for (std::size_t i = 0; i < order.size() || i < params.size(); ++i) {
      if (i >= order.size() || i >= params.size() || order[i] != params[i].name) {
        return Why(why, "parameter_order differs from the model's");
      }
    }
  }
  if (!j.contains("params") || !j["params"].is_object()) return Why(why, "'params' is missing");
  d->theta.resize(n);
  d->sigma.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const std::string& name = params[static_cast<std::size_t>(i)].name;
    const auto it = j["params"].find(name);
    if (it == j["params"].end() || !it->is_object() || !it->contains("value") ||
        !(*it)["value"].is_number() || !std::isfinite((*it)["value"].get<double>())) {
      return Why(why, "parameter '" + name + "' has no finite value");
    }
    d->theta[i] = (*it)["value"].get<double>();
    if (!ReadNumberOrNull(it->value("sigma", nlohmann::json()), &d->sigma[i])) {
      return Why(why, "parameter '" + name + "': sigma is not a number");
    }
  }
  if (j.contains("covariance") && !j["covariance"].empty()) {
    const auto& c = j["covariance"];
    if (!c.is_array() || c.size() != params.size()) return Why(why, "covariance is not N x N");
    d->covariance.resize(n, n);
    for (Eigen::Index r = 0; r < n; ++r) {
      const auto& row = c[static_cast<std::size_t>(r)];
      if (!row.is_array() || row.size() != params.size())
        return Why(why, "covariance is not N x N");
      for (Eigen::Index k = 0; k < n; ++k) {
        if (!ReadNumberOrNull(row[static_cast<std::size_t>(k)], &d->covariance(r, k))) {
          return Why(why, "covariance holds a non-number");
        }
      }
    }
  }
  return true;
}

// The estimate's summary: version, software, time, gauge, rank, dof, chi2, p, the identified
// drift, the two-sided fit check, the gate's verdict and an operator's override.
bool ReadSummary(const nlohmann::json& j, CalibrationDocument* d, std::string* why) {
  if (j.contains("version") && !j["version"].is_number_integer()) return Why(why, "bad version");
  d->version = j.value("version", 0);
  for (auto [key, target] : {std::pair{"software", &d->software}, std::pair{"time", &d->time},
                             std::pair{"gauge", &d->gauge}}) {
    if (j.contains(key) && !j[key].is_string())
      return Why(why, fmt::format("'{}' is not text", key));
    *target = j.value(key, std::string());
  }
  if ((j.contains("rank") && !j["rank"].is_number_integer()) ||
      (j.contains("dof") && !j["dof"].is_number_integer()) ||
      (j.contains("chi2") && !j["chi2"].is_number()) ||
      (j.contains("p_value") && !j["p_value"].is_number())) {
    return Why(why, "rank, dof, chi2 or p_value is not a number");
  }
  d->rank = j.value("rank", 0);
  d->dof = j.value("dof", 0);
  d->chi2 = j.value("chi2", 0.0);
  d->p_value = j.value("p_value", 1.0);
  if (j.contains("calibrator") && j["calibrator"].is_object() &&
      j["calibrator"].contains("drift_scale") && j["calibrator"]["drift_scale"].is_object()) {
    const auto& s = j["calibrator"]["drift_scale"];
    if (s.value("identified", false) && s.contains("data_scale") && s["data_scale"].is_number()) {
      d->drift_scale = s["data_scale"].get<double>();
      if (s.contains("data_log_sigma") && s["data_log_sigma"].is_number()) {
        d->drift_scale_log_sigma = s["data_log_sigma"].get<double>();
      }
      if (s.contains("used") && s["used"].is_number())
        d->drift_scale_used = s["used"].get<double>();
    }
  }
  if (j.contains("fit_check") && j["fit_check"].is_object()) {
    const auto& f = j["fit_check"];
    if (f.contains("verdict") && f["verdict"].is_string()) d->fit_verdict = f["verdict"];
    if (f.contains("message") && f["message"].is_string()) d->fit_message = f["message"];
  }
  if (!j.contains("gate") || !ReadGate(j["gate"], &d->gate)) {
    return Why(why, "'gate' is missing or malformed");
  }
  d->override_who = j.value("override", nlohmann::json());
  return true;
}

// "provenance": the device's identity, the poses and (when recorded) their records.
bool ReadProvenance(const nlohmann::json& j, CalibrationDocument* d, std::string* why) {
  const nlohmann::json provenance = j.value("provenance", nlohmann::json::object());
  if (!provenance.is_object()) return Why(why, "provenance is not an object");
  d->identity = provenance.value("device_identity", nlohmann::json());
  if (provenance.contains("poses")) {
    if (!provenance["poses"].is_array()) return Why(why, "provenance.poses is not a list");
    for (const auto& p : provenance["poses"]) {
      TablePose pose;
      if (!ParseTablePose(p, &pose, nullptr)) {
        return Why(why, "provenance.poses holds a pose without angles");
      }
      d->poses.push_back(pose);
    }
  }
  if (provenance.contains("records")) {
    if (!provenance["records"].is_array()) return Why(why, "provenance.records is not a list");
    for (std::size_t i = 0; i < provenance["records"].size(); ++i) {
      PoseRecord r;
      std::string record_why;
      if (!ParsePoseRecord(provenance["records"][i], &r, &record_why)) {
        return Why(why, fmt::format("provenance.records[{}]: {}", i, record_why));
      }
      d->records.push_back(r);
    }
  }
  return true;
}

// The calibrator's options (the class's by default) and the gate's tolerances (the class's, or
// the document's).
bool ReadCalibratorAndTolerances(const nlohmann::json& j, const MeasurementModel& model,
                                 CalibrationDocument* d, std::string* why) {
  SensorClass industrial = IndustrialClass();
  d->calibrator = OptionsForClass(model, industrial);
  if (j.contains("calibrator") &&
      !ReadCalibrator(j["calibrator"], &d->calibrator, &d->sensor_class)) {
    return Why(why, "'calibrator' is malformed");
  }
  return ReadTolerances(j, model, d->sensor_class, &d->tolerances, &d->tolerances_recorded, why);
}

}  // namespace

bool ReadTolerances(const nlohmann::json& j, const MeasurementModel& model,
                    const std::string& sensor_class, std::map<std::string, double>* tolerances,
                    bool* recorded, std::string* why) {
  GateOptions gate;
  GateTolerancesForClass(sensor_class.empty() ? "industrial" : sensor_class, &gate.tolerances);
  tolerances->clear();
  *recorded = false;
  for (int i : GatedParameters(model)) {
    const ParameterInfo& p = model.parameters()[static_cast<std::size_t>(i)];
    (*tolerances)[p.name] = ToleranceFor(p, gate);
  }
  if (j.contains("tolerances")) {
    if (!j["tolerances"].is_object()) return Why(why, "'tolerances' is not an object");
    tolerances->clear();
    for (const auto& [name, v] : j["tolerances"].items()) {
      if (!v.is_number() || !(v.get<double>() > 0) || model.index_of(name) < 0) {
        return Why(why, "tolerance of '" + name + "' is not a positive number of a parameter");
      }
      (*tolerances)[name] = v.get<double>();
    }
    *recorded = true;
  }
  return true;
}

bool ParseCalibrationDocument(const nlohmann::json& j, CalibrationDocument* out,
                              std::string* error) {
  auto fail = [&](const std::string& what) {
    if (error) *error = what;
    return false;
  };
  if (!j.is_object()) return fail("a calibration must be a JSON object");
  for (const char* key : {"device", "model"}) {
    if (!j.contains(key) || !j[key].is_string() || j[key].get<std::string>().empty()) {
      return fail(fmt::format("'{}' is missing or not a non-empty string", key));
    }
  }
  CalibrationDocument d;
  d.device = j["device"].get<std::string>();
  d.model = j["model"].get<std::string>();
  const std::string where = d.device + " " + d.model + ": ";
  auto bad = [&](const std::string& what) { return fail(where + what); };
  if (j.contains("schema") && j["schema"] != 1) {
    return bad("schema " + j["schema"].dump() + " is not supported (1 is)");
  }
  if (j.contains("context")) {
    std::string why;
    if (!ParseModelContext(j["context"], &d.context, &why)) return bad(why);
    d.context_recorded = true;
  }
  std::string why;
  d.measurement_model = MakeModel(d.model, d.context, &why);
  if (!d.measurement_model) return bad(why);
  const MeasurementModel& model = *d.measurement_model;

  if (!ReadParameters(j, model, &d, &why)) return bad(why);
  if (!ReadSummary(j, &d, &why)) return bad(why);
  if (!ReadProvenance(j, &d, &why)) return bad(why);
  if (!ReadCalibratorAndTolerances(j, model, &d, &why)) return bad(why);
  *out = std::move(d);
  return true;
}

}  // namespace turncal::protocol
