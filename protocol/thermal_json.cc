#include "protocol/thermal_json.h"

#include <fmt/format.h>

#include <cmath>
#include <limits>

#include "protocol/calibration_json.h"
#include "protocol/observability_json.h"
#include "protocol/sequencer_json.h"
#include "turncal/version.h"

namespace turncal::protocol {

namespace {

nlohmann::json NumberOrNull(double v) { return std::isfinite(v) ? nlohmann::json(v) : nullptr; }

}  // namespace

nlohmann::json ParamsAtJson(const ThermalEstimate& e, double temp_c) {
  nlohmann::json params = nlohmann::json::object();
  if (!e.ok) return params;
  const Eigen::VectorXd theta = e.ThetaAt(temp_c);
  const Eigen::VectorXd sigma = e.SigmaAt(temp_c);
  for (std::size_t p = 0; p < e.parameters.size(); ++p) {
    const auto k = static_cast<Eigen::Index>(p);
    params[e.parameters[p].name] = {{"value", theta[k]}, {"sigma", NumberOrNull(sigma[k])}};
  }
  return params;
}

nlohmann::json ToJson(const ThermalEstimate& e) {
  nlohmann::json orders = nlohmann::json::object(), reasons = nlohmann::json::object();
  for (std::size_t p = 0; p < e.parameters.size(); ++p) {
    orders[e.parameters[p].name] = p < e.basis.orders.size() ? e.basis.orders[p] : 0;
    if (p < e.order_reasons.size()) reasons[e.parameters[p].name] = e.order_reasons[p];
  }
  nlohmann::json coefficients = nlohmann::json::object(), names = nlohmann::json::array();
  for (std::size_t k = 0; k < e.coefficient_names.size(); ++k) {
    const auto i = static_cast<Eigen::Index>(k);
    coefficients[e.coefficient_names[k]] = {{"value", e.coefficients[i]},
                                            {"sigma", NumberOrNull(e.sigma[i])}};
    names.push_back(e.coefficient_names[k]);
  }
  nlohmann::json j = {{"ok", e.ok},
                      {"t0_c", e.basis.t0_c},
                      {"t_min_c", NumberOrNull(e.t_min_c)},
                      {"t_max_c", NumberOrNull(e.t_max_c)},
                      {"distinct_temperatures", e.distinct_temperatures},
                      {"orders", orders},
                      {"order_reasons", reasons},
                      {"coefficients", coefficients},
                      {"coefficient_order", names},
                      {"covariance", CovarianceJson(e.covariance)},
                      {"poses", e.poses},
                      {"rank", e.rank},
                      {"chi2", e.chi2},
                      {"dof", e.dof},
                      {"p_value", e.p_value},
                      {"covariance_scale", e.covariance_scale},
                      {"fit_check", ToString(e.fit.verdict)},
                      {"warnings", e.warnings}};
  if (!e.ok) j["error"] = e.error;
  if (e.ok) {
    j["at"] = {{"t_min", ParamsAtJson(e, e.t_min_c)},
               {"t0", ParamsAtJson(e, e.basis.t0_c)},
               {"t_max", ParamsAtJson(e, e.t_max_c)}};
  }
  return j;
}

nlohmann::json ThermalCalibrationJson(const ThermalCalibrationInput& in) {
  const ThermalEstimate& e = *in.estimate;
  nlohmann::json records = nlohmann::json::array();
  const SensorKind sensor = in.model->sensor();
  for (PoseRecord r : *in.records) {
    if (sensor != SensorKind::kAccelerometer) r.acc.reset();
    if (sensor != SensorKind::kGyroscope) r.gyr.reset();
    if (sensor != SensorKind::kMagnetometer) r.mag.reset();
    r.move_in.reset();  // not used over temperature
    records.push_back(ToJson(r));
  }
  return {{"schema", 1},
          {"class", "CALIBRATION"},
          {"kind", "thermal"},
          {"device", in.device},
          {"model", in.name},
          {"base_model", in.model->name()},
          {"version", in.version},
          {"software", kVersion},
          {"temperature", ToJson(e)},
          {"gate", turncal::ToJson(in.gate)},
          {"tolerances", TolerancesJson(*in.model, in.gate_options)},
          {"context", ToJson(in.context)},
          {"calibrator", CalibratorJson(in.calibrator, in.sensor_class)},
          {"provenance", {{"records", records}, {"device_identity", in.identity}}}};
}

bool IsThermalCalibration(const nlohmann::json& j) {
  return j.is_object() && j.value("kind", nlohmann::json()) == "thermal";
}

bool ReadThermalEstimate(const MeasurementModel& model, const nlohmann::json& doc,
                         ThermalEstimate* out, std::string* why) {
  auto fail = [&](const std::string& what) {
    if (why) *why = what;
    return false;
  };
  if (!doc.is_object() || !doc.contains("temperature") || !doc["temperature"].is_object()) {
    return fail("no \"temperature\" section");
  }
  const nlohmann::json& t = doc["temperature"];
  for (const char* key : {"t0_c", "t_min_c", "t_max_c"}) {
    if (!t.value(key, nlohmann::json()).is_number())
      return fail(fmt::format("{} is not a number", key));
  }
  if (!t.value("orders", nlohmann::json()).is_object() ||
      !t.value("coefficients", nlohmann::json()).is_object()) {
    return fail("orders or coefficients are missing");
  }
  ThermalEstimate e;
  e.model = model.name();
  e.parameters = model.parameters();
  e.basis.t0_c = t["t0_c"].get<double>();
  e.basis.scale_c = 1.0;
  for (const auto& p : e.parameters) {
    const auto it = t["orders"].find(p.name);
    if (it == t["orders"].end() || !it->is_number_integer() || it->get<int>() < 0 ||
        it->get<int>() > 10) {
      return fail("no order for " + p.name);
    }
    e.basis.orders.push_back(it->get<int>());
  }
  const int n = e.basis.num_coefficients();
  e.coefficients.resize(n);
  e.sigma.resize(n);
  for (int k = 0; k < n; ++k) {
    const std::string name = e.basis.CoefficientName(e.parameters, k);
    const auto it = t["coefficients"].find(name);
    if (it == t["coefficients"].end() || !it->is_object() || !(*it)["value"].is_number()) {
      return fail("no coefficient " + name);
    }
    e.coefficient_names.push_back(name);
    e.coefficients[k] = (*it)["value"].get<double>();
    const auto& s = (*it).value("sigma", nlohmann::json());
    e.sigma[k] = s.is_number() ? s.get<double>() : std::numeric_limits<double>::quiet_NaN();
  }
  e.covariance.resize(0, 0);
  const auto& cov = t.value("covariance", nlohmann::json());
  if (cov.is_array() && static_cast<int>(cov.size()) == n) {
    Eigen::MatrixXd c(n, n);
    bool good = true;
    for (int r = 0; good && r < n; ++r) {
      const auto& row = cov[static_cast<std::size_t>(r)];
      good = row.is_array() && static_cast<int>(row.size()) == n;
      for (int k = 0; good && k < n; ++k) {
        good = row[static_cast<std::size_t>(k)].is_number();
        if (good) c(r, k) = row[static_cast<std::size_t>(k)].get<double>();
      }
    }
    if (good) e.covariance = c;
  }
  e.t_min_c = t["t_min_c"].get<double>();
  e.t_max_c = t["t_max_c"].get<double>();
  if (!(e.t_min_c <= e.t_max_c)) return fail("t_min_c is above t_max_c");
  e.distinct_temperatures = t.value("distinct_temperatures", 0);
  e.poses = t.value("poses", 0);
  e.ok = e.coefficients.allFinite();
  if (!e.ok) return fail("a coefficient is not finite");
  *out = std::move(e);
  return true;
}

bool ParseThermalCalibrationDocument(const nlohmann::json& j, ThermalCalibrationDocument* out,
                                     std::string* error) {
  auto fail = [&](const std::string& what) {
    if (error) *error = what;
    return false;
  };
  if (!IsThermalCalibration(j)) return fail("not a calibration over temperature (\"kind\")");
  for (const char* key : {"device", "model", "base_model"}) {
    if (!j.contains(key) || !j[key].is_string() || j[key].get<std::string>().empty()) {
      return fail(fmt::format("'{}' is missing or not a non-empty string", key));
    }
  }
  ThermalCalibrationDocument d;
  d.device = j["device"].get<std::string>();
  d.model = j["model"].get<std::string>();
  d.base_model = j["base_model"].get<std::string>();
  const std::string where = d.device + " " + d.model + ": ";
  auto bad = [&](const std::string& what) { return fail(where + what); };
  if (j.contains("schema") && j["schema"] != 1) {
    return bad("schema " + j["schema"].dump() + " is not supported (1 is)");
  }
  d.version =
      j.value("version", nlohmann::json()).is_number_integer() ? j["version"].get<int>() : 0;
  for (auto [key, to] : {std::pair{"software", &d.software}, std::pair{"time", &d.time}}) {
    if (j.contains(key) && j[key].is_string()) *to = j[key].get<std::string>();
  }
  std::string why;
  if (j.contains("context")) {
    if (!ParseModelContext(j["context"], &d.context, &why)) return bad(why);
    d.context_recorded = true;
  }
  d.measurement_model = MakeModel(d.base_model, d.context, &why);
  if (!d.measurement_model) return bad(why);
  const MeasurementModel& model = *d.measurement_model;
  if (!ReadThermalEstimate(model, j, &d.estimate, &why)) return bad(why);
  const int n = d.estimate.basis.num_coefficients();
  d.covariance_complete = d.estimate.covariance.rows() == n && d.estimate.covariance.allFinite();
  const nlohmann::json& t = j["temperature"];
  d.chi2 = t.value("chi2", 0.0);
  d.dof = t.value("dof", 0);
  d.p_value = t.value("p_value", 1.0);
  d.rank = t.value("rank", 0);
  if (j.contains("calibrator") && j["calibrator"].is_object()) {
    d.sensor_class = j["calibrator"].value("sensor_class", std::string());
  }
  if (!ReadTolerances(j, model, d.sensor_class, &d.tolerances, &d.tolerances_recorded, &why)) {
    return bad(why);
  }
  *out = std::move(d);
  return true;
}

}  // namespace turncal::protocol
