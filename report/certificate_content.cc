// The certificate's content (report/certificate.h): everything the page shows, taken from one
// calibration document and put in one JSON object, so that the page and its embedded data block
// say the same and a registry can compare the data with its records.

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <set>

#include "core/modeling/free_model.h"
#include "protocol/calibration_json.h"
#include "protocol/free_json.h"
#include "protocol/thermal_json.h"
#include "report/certificate.h"
#include "report/drift_section.h"
#include "turncal/version.h"

namespace turncal::report {
namespace {

using Json = nlohmann::json;

// The GUM's coverage factor for an expanded uncertainty of about 95 % (normal distribution).
constexpr double kCertCoverageFactor = 2.0;

// A number, or null where it is not finite (JSON has no NaN).
Json CertNumber(double v) { return std::isfinite(v) ? Json(v) : Json(); }

double CertNumberOr(const Json& j, const char* key, double fallback) {
  if (!j.is_object()) return fallback;
  const auto it = j.find(key);
  return it != j.end() && it->is_number() ? it->get<double>() : fallback;
}

std::string CertString(const Json& j, const char* key) {
  if (!j.is_object()) return "";
  const auto it = j.find(key);
  return it != j.end() && it->is_string() ? it->get<std::string>() : "";
}

double CertMedian(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

// A value as the table shows it: the unit's scale, but no offset (alpha3 in degrees, not its
// deviation from 90 degrees: a certificate states the value).
std::pair<double, std::string> CertShown(const ParameterInfo& p, double v) {
  if (!std::isfinite(v)) return {NAN, ""};
  const DisplayQuantity q = ForDisplay(p, v, /*is_sigma=*/true);
  return {q.value, q.unit};
}

// One parameter's row. `tolerance` < 0: not gated. `judged` is the parameter as the gate judges
// its sigma (a free model's gains k as scale factors).
Json CertParameter(const ParameterInfo& p, const ParameterInfo& judged, double value, double sigma,
                   double tolerance) {
  const bool gated = tolerance >= 0;
  const bool determined = std::isfinite(sigma);
  std::string check = "not gated";
  if (!determined) {
    check = "not determined";
  } else if (gated) {
    check = sigma <= tolerance ? "within" : "exceeds";  // the gate's test: u <= tolerance
  }
  const auto [value_shown, value_unit] = CertShown(p, value);
  const auto [u_shown, u_unit] = CertShown(judged, sigma);
  const std::string unit = determined ? u_unit : CertShown(judged, 1.0).second;
  return {{"name", p.name},
          {"kind", ToString(p.kind)},
          {"unit", ToString(p.unit)},
          {"value", value},
          {"u", CertNumber(sigma)},
          {"U", CertNumber(kCertCoverageFactor * sigma)},
          {"tolerance_u", gated ? Json(tolerance) : Json()},
          {"check", check},
          {"shown",
           {{"value", CertNumber(value_shown)},
            {"value_unit", value_unit},
            {"u", CertNumber(u_shown)},
            {"U", CertNumber(kCertCoverageFactor * u_shown)},
            {"tolerance_u", gated ? CertNumber(CertShown(judged, tolerance).first) : Json()},
            {"unit", unit}}}};
}

// Identity: the device's own dialogue (provenance.device_identity), completed or corrected by
// the caller's (a registry's).
Json CertIdentity(const std::string& device, const Json& from_device, const Json& extra) {
  Json merged = from_device.is_object() ? from_device : Json::object();
  if (extra.is_object()) {
    for (const auto& [key, value] : extra.items()) merged[key] = value;
  }
  auto text = [&](std::initializer_list<const char*> keys) -> Json {
    for (const char* key : keys) {
      const auto it = merged.find(key);
      if (it == merged.end() || it->is_null()) continue;
      const std::string s = it->is_string() ? it->get<std::string>() : it->dump();
      if (!s.empty()) return s;
    }
    return Json();
  };
  Json model_name = text({"model_name", "product_code"});
  if (const Json number = text({"model_number"}); !number.is_null() && !model_name.is_null()) {
    model_name = model_name.get<std::string>() + " (" + number.get<std::string>() + ")";
  }
  return {{"name", device},
          {"serial", text({"serial", "device_id"})},
          {"model_name", model_name},
          {"firmware", text({"firmware"})},
          {"protocol", text({"protocol"})},
          {"rate_hz", CertNumber(CertNumberOr(merged, "rate_hz", NAN))},
          {"reported_by_device", from_device.is_object() && !from_device.empty()},
          {"stored_calibration_recorded", merged.contains("stored_calibration")}};
}

// What the records say about the session: how long each pose was held, the sensor's
// temperature, how long it all took. Times are the device's own clock where every record has it
// (a replay or a sped-up simulation runs the host's clock at another pace), else the host's.
Json CertRecords(const Json& records) {
  std::vector<double> dwell_s, temp_c;
  double first_s = INFINITY, last_s = -INFINITY;
  bool sensor_clock = records.is_array() && !records.empty();
  for (const Json& r : records.is_array() ? records : Json::array()) {
    sensor_clock = sensor_clock && std::isfinite(CertNumberOr(r, "t_sensor_start", NAN)) &&
                   std::isfinite(CertNumberOr(r, "t_sensor_end", NAN));
  }
  const char* start = sensor_clock ? "t_sensor_start" : "t_start";
  const char* end = sensor_clock ? "t_sensor_end" : "t_end";
  if (records.is_array()) {
    for (const Json& r : records) {
      const double t0 = CertNumberOr(r, start, NAN), t1 = CertNumberOr(r, end, NAN);
      if (std::isfinite(t0) && std::isfinite(t1) && t1 >= t0) {
        dwell_s.push_back(t1 - t0);
        first_s = std::min(first_s, t0);
        last_s = std::max(last_s, t1);
      }
      if (const double t = CertNumberOr(r, "temp", NAN); std::isfinite(t)) temp_c.push_back(t);
    }
  }
  const auto [tmin, tmax] = std::minmax_element(temp_c.begin(), temp_c.end());
  return {{"records", records.is_array() ? records.size() : 0},
          {"dwell_s_median", CertNumber(CertMedian(dwell_s))},
          {"session_s", CertNumber(last_s - first_s)},
          {"clock", sensor_clock ? "sensor" : "host"},
          {"temperature_c", temp_c.empty() ? Json() : Json::array({*tmin, *tmax})}};
}

// The table's static poses (angle ranges, distinct orientations) and rate segments.
Json CertPoses(const Json& poses) {
  int statics = 0;
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  std::set<std::string> orientations, rate_axes;
  std::set<double> rates_dps;
  const char* axes[3] = {"phi_deg", "gamma_deg", "psi_deg"};
  for (const Json& p : poses.is_array() ? poses : Json::array()) {
    if (p.contains("rate_axis")) {
      rate_axes.insert(CertString(p, "rate_axis"));
      rates_dps.insert(CertNumberOr(p, "rate_dps", NAN));
      continue;
    }
    ++statics;
    std::string key;
    for (int a = 0; a < 3; ++a) {
      const double v = CertNumberOr(p, axes[a], NAN);
      lo[a] = std::min(lo[a], v);
      hi[a] = std::max(hi[a], v);
      key += fmt::format("{:.3f},", v);
    }
    orientations.insert(key);
  }
  Json ranges = Json::object();
  for (int a = 0; a < 3; ++a) {
    if (statics > 0) ranges[axes[a]] = {CertNumber(lo[a]), CertNumber(hi[a])};
  }
  const int segments = poses.is_array() ? static_cast<int>(poses.size()) - statics : 0;
  return {{"static_poses", statics},
          {"distinct_orientations", orientations.size()},
          {"angle_ranges_deg", ranges},
          {"rate_segments", segments},
          {"rate_axes", Json(std::vector<std::string>(rate_axes.begin(), rate_axes.end()))},
          {"rates_dps", Json(std::vector<double>(rates_dps.begin(), rates_dps.end()))}};
}

// The turntable environment: gravity and the field in the level frame, their magnitudes and the
// field's dip (below the horizontal) and declination.
Json CertTableEnvironment(const ModelContext& c, bool recorded) {
  const Eigen::Vector3d& g = c.reference.g_ned;
  const Eigen::Vector3d& b = c.reference.B_ned;
  constexpr double kDeg = 180.0 / M_PI;
  return {{"recorded", recorded},
          {"g_ned_mps2", {g.x(), g.y(), g.z()}},
          {"gravity_mps2", g.norm()},
          {"B_ned", {b.x(), b.y(), b.z()}},
          {"field_magnitude", b.norm()},
          {"field_dip_deg", std::atan2(b.z(), std::hypot(b.x(), b.y())) * kDeg},
          {"field_declination_deg", std::atan2(b.y(), b.x()) * kDeg},
          {"accel_output_frame", ToString(c.accel_output_frame)},
          {"mounting_is_identity", c.mounting.isIdentity(1e-12)}};
}

Json CertFreeEnvironment(const FreeContext& c) {
  return {{"recorded", true},
          {"gravity_mps2", c.gravity_mps2},
          {"field_magnitude", CertNumber(c.field_magnitude)},
          {"field_dip_deg", CertNumber(c.dip_deg)},
          {"latitude_deg", CertNumber(c.latitude_deg)}};
}

// The calibrator's noise model: the class, white noise, loss and drift it weighed poses with.
Json CertCalibrator(const Json& calibrator, const std::string& sensor_class) {
  const Json drift = calibrator.is_object() ? calibrator.value("drift", Json()) : Json();
  Json gm_sigma;
  if (drift.is_object() && drift.contains("gauss_markov_sigma")) {
    gm_sigma = drift["gauss_markov_sigma"];
  }
  const std::string recorded_class = CertString(calibrator, "sensor_class");
  return {{"sensor_class", recorded_class.empty() ? sensor_class : recorded_class},
          {"noise_density", CertNumber(CertNumberOr(calibrator, "noise_density", NAN))},
          {"loss", CertString(calibrator, "loss")},
          {"loss_scale", CertNumber(CertNumberOr(calibrator, "loss_scale", NAN))},
          {"drift_gauss_markov_sigma", gm_sigma},
          {"drift_gauss_markov_tau_s", CertNumber(CertNumberOr(drift, "gauss_markov_tau_s", NAN))}};
}

// A calibration over temperature (issue 36): each parameter's row at T0 (value, u, U) with its
// value and u at the range's ends and its worst u over the range, which is what the gate
// compares with the tolerance; and the polynomials' coefficients (unit per degC^j about T0).
// Without the whole covariance only sigma at T0 is known: u at the ends is then not stated.
void CertThermal(const protocol::ThermalCalibrationDocument& doc, Json* parameters,
                 Json* temperature) {
  const ThermalEstimate& e = doc.estimate;
  const auto& infos = doc.measurement_model->parameters();
  const double t0 = e.basis.t0_c, lo = e.t_min_c, hi = e.t_max_c;
  const Eigen::VectorXd nan = Eigen::VectorXd::Constant(e.basis.num_parameters(), NAN);
  auto sigma_at = [&](double t) { return doc.covariance_complete ? e.SigmaAt(t) : nan; };
  Eigen::VectorXd sigma_t0(e.basis.num_parameters());
  for (int p = 0; p < e.basis.num_parameters(); ++p) sigma_t0[p] = e.sigma[e.basis.index(p, 0)];
  if (doc.covariance_complete) sigma_t0 = e.SigmaAt(t0);
  const Eigen::VectorXd theta_t0 = e.ThetaAt(t0), theta_lo = e.ThetaAt(lo),
                        theta_hi = e.ThetaAt(hi);
  const Eigen::VectorXd sigma_lo = sigma_at(lo), sigma_hi = sigma_at(hi);
  // The worst u over the range on the gate's grid (41 temperatures, the ends included).
  constexpr int kGrid = 41;
  Eigen::VectorXd worst = Eigen::VectorXd::Constant(e.basis.num_parameters(), -1.0);
  Eigen::VectorXd worst_at = Eigen::VectorXd::Constant(e.basis.num_parameters(), NAN);
  for (int g = 0; g < kGrid && doc.covariance_complete; ++g) {
    const double t = lo + (hi - lo) * g / (kGrid - 1);
    const Eigen::VectorXd s = e.SigmaAt(t);
    for (int p = 0; p < s.size(); ++p) {
      if (!(s[p] <= worst[p])) worst[p] = s[p], worst_at[p] = t;
    }
  }
  for (std::size_t i = 0; i < infos.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    const auto tol = doc.tolerances.find(infos[i].name);
    const double tolerance = tol == doc.tolerances.end() ? -1.0 : tol->second;
    Json row = CertParameter(infos[i], infos[i], theta_t0[k], sigma_t0[k], tolerance);
    auto at = [&](double value, double sigma) {
      const Json r = CertParameter(infos[i], infos[i], value, sigma, -1.0);
      return Json{{"value", r["value"]}, {"u", r["u"]}, {"U", r["U"]}, {"shown", r["shown"]}};
    };
    const double w = doc.covariance_complete ? worst[k] : NAN;
    row["order"] = e.basis.orders[i];
    row["t_min"] = at(theta_lo[k], sigma_lo[k]);
    row["t_max"] = at(theta_hi[k], sigma_hi[k]);
    row["u_worst"] = CertNumber(w);
    row["u_worst_at_c"] = CertNumber(std::isfinite(w) ? worst_at[k] : NAN);
    row["shown"]["u_worst"] = CertNumber(std::isfinite(w) ? CertShown(infos[i], w).first : NAN);
    if (tolerance >= 0 && std::isfinite(sigma_t0[k])) {
      row["check"] = !std::isfinite(w) ? "not determined" : w <= tolerance ? "within" : "exceeds";
    }
    parameters->push_back(row);
  }
  Json coefficients = Json::array();
  for (int n = 0; n < e.basis.num_coefficients(); ++n) {
    int param = 0, power = 0;
    for (int p = 0; p < e.basis.num_parameters(); ++p) {
      for (int j = 0; j <= e.basis.orders[static_cast<std::size_t>(p)]; ++j) {
        if (e.basis.index(p, j) == n) param = p, power = j;
      }
    }
    const ParameterInfo& info = infos[static_cast<std::size_t>(param)];
    const double value = e.coefficients[n], sigma = e.sigma[n];
    const auto [value_shown, unit] = CertShown(info, value);
    const auto [u_shown, u_unit] = CertShown(info, sigma);
    const std::string per = power == 0 ? "" : power == 1 ? "/degC" : fmt::format("/degC^{}", power);
    coefficients.push_back({{"name", e.basis.CoefficientName(infos, n)},
                            {"parameter", info.name},
                            {"power", power},
                            {"unit", ToString(info.unit) + per},
                            {"value", value},
                            {"u", CertNumber(sigma)},
                            {"U", CertNumber(kCertCoverageFactor * sigma)},
                            {"shown",
                             {{"value", CertNumber(value_shown)},
                              {"u", CertNumber(u_shown)},
                              {"U", CertNumber(kCertCoverageFactor * u_shown)},
                              {"unit", (std::isfinite(sigma) ? u_unit : unit) + per}}}});
  }
  *temperature = {{"t0_c", t0},
                  {"t_min_c", lo},
                  {"t_max_c", hi},
                  {"distinct_temperatures", e.distinct_temperatures},
                  {"poses", e.poses},
                  {"covariance_complete", doc.covariance_complete},
                  {"coefficients", coefficients}};
}

// The table's poses of a calibration over temperature: its records' (it keeps no pose list).
Json CertRecordPoses(const Json& records) {
  Json poses = Json::array();
  for (const Json& r : records.is_array() ? records : Json::array()) {
    if (r.is_object() && r.contains("pose")) poses.push_back(r["pose"]);
  }
  return poses;
}

std::vector<std::string> CertStrings(const Json& j, const char* key) {
  std::vector<std::string> out;
  if (!j.is_object() || !j.contains(key) || !j[key].is_array()) return out;
  for (const Json& s : j[key]) out.push_back(s.is_string() ? s.get<std::string>() : s.dump());
  return out;
}

}  // namespace

std::string CertificateNumber(const std::string& station, const std::string& device,
                              const std::string& model, int version) {
  std::string n =
      fmt::format("{}-{}-{}-v{}", station.empty() ? "unknown" : station, device, model, version);
  for (char& ch : n) {
    const bool plain =
        std::isalnum(static_cast<unsigned char>(ch)) || ch == '.' || ch == '_' || ch == '-';
    if (!plain) ch = '_';
  }
  return n;
}

bool CertificateContent(const CertificateSource& source, Json* content, std::string* error) {
  const Json& c = source.calibration;
  if (!c.is_object()) {
    *error = "the calibration is not a JSON object";
    return false;
  }
  const bool free = protocol::IsFreeCalibration(c);
  const bool thermal = protocol::IsThermalCalibration(c);
  std::string device, model, time, software, sensor;
  int version = 0;
  Json parameters = Json::array(), environment, procedure, temperature;
  Json fit_source = c;     // where chi2, dof, p_value and rank are
  std::size_t fitted = 0;  // the fit's unknowns
  const Json params = c.value("params", Json::object());
  const Json provenance =
      c.contains("provenance") && c["provenance"].is_object() ? c["provenance"] : Json::object();
  if (free) {
    protocol::FreeCalibrationDocument doc;
    if (!protocol::ParseFreeCalibration(c, &doc, error)) return false;
    auto m = MakeFreeModel(doc.model, doc.context, error);
    if (!m) return false;
    const auto& infos = m->parameters();
    for (std::size_t i = 0; i < infos.size(); ++i) {
      // Without a precision gate (free_gate.precision null) no parameter is gated.
      ParameterInfo judged = infos[i];
      const double tolerance = doc.options.precision
                                   ? FreeToleranceFor(infos[i], *doc.options.precision, &judged)
                                   : -1.0;
      const double sigma = CertNumberOr(params.value(infos[i].name, Json()), "sigma", NAN);
      parameters.push_back(CertParameter(infos[i], judged, doc.theta[static_cast<Eigen::Index>(i)],
                                         sigma, tolerance));
    }
    device = doc.device, model = doc.model, time = doc.time, software = doc.software;
    version = doc.version, sensor = ToString(m->sensor());
    environment = CertFreeEnvironment(doc.context);
    procedure = {{"pose_source", "free"}, {"poses", CertPoses(Json::array())}};
  } else if (thermal) {
    protocol::ThermalCalibrationDocument doc;
    if (!protocol::ParseThermalCalibrationDocument(c, &doc, error)) return false;
    CertThermal(doc, &parameters, &temperature);
    device = doc.device, model = doc.model, time = doc.time, software = doc.software;
    version = doc.version, sensor = ToString(doc.measurement_model->sensor());
    environment = CertTableEnvironment(doc.context, doc.context_recorded);
    procedure = {{"pose_source", "turntable"},
                 {"poses", CertPoses(CertRecordPoses(provenance.value("records", Json())))},
                 {"tolerances_recorded", doc.tolerances_recorded}};
    fit_source = c["temperature"];
    fitted = static_cast<std::size_t>(doc.estimate.basis.num_coefficients());
  } else {
    protocol::CalibrationDocument doc;
    if (!protocol::ParseCalibrationDocument(c, &doc, error)) return false;
    const auto& infos = doc.measurement_model->parameters();
    for (std::size_t i = 0; i < infos.size(); ++i) {
      const auto k = static_cast<Eigen::Index>(i);
      const auto tol = doc.tolerances.find(infos[i].name);
      parameters.push_back(CertParameter(infos[i], infos[i], doc.theta[k], doc.sigma[k],
                                         tol == doc.tolerances.end() ? -1.0 : tol->second));
    }
    device = doc.device, model = doc.model, time = doc.time, software = doc.software;
    version = doc.version, sensor = ToString(doc.measurement_model->sensor());
    environment = CertTableEnvironment(doc.context, doc.context_recorded);
    procedure = {{"pose_source", "turntable"},
                 {"poses", CertPoses(provenance.value("poses", Json::array()))},
                 {"tolerances_recorded", doc.tolerances_recorded}};
  }
  const Json records = CertRecords(provenance.value("records", Json::array()));
  environment["temperature_c"] = records["temperature_c"];
  procedure["records"] = records["records"];
  procedure["dwell_s_median"] = records["dwell_s_median"];
  procedure["session_s"] = records["session_s"];
  procedure["clock"] = records["clock"];
  procedure["calibrator"] =
      CertCalibrator(c.value("calibrator", Json()), CertString(c, "sensor_class"));

  const Json gate = c.value("gate", Json::object());
  const bool pass = gate.is_object() && gate.contains("pass") && gate["pass"] == true;
  const std::string station = source.station.empty() ? "unknown" : source.station;
  *content = {{"schema", "turncal-certificate/1"},
              {"number", CertificateNumber(source.station, device, model, version)},
              {"station", station},
              {"source", source.source},
              {"issued_utc", source.issued_utc},
              {"device",
               CertIdentity(device, provenance.value("device_identity", Json()), source.identity)},
              {"calibration",
               {{"model", model},
                {"sensor", sensor},
                {"version", version},
                {"time_utc", time},
                {"software", software}}},
              {"environment", environment},
              {"procedure", procedure},
              {"coverage_factor", kCertCoverageFactor},
              {"parameters", parameters},
              {"verdict",
               {{"pass", pass},
                {"text", pass ? "PASS" : "NOT PASSED"},
                {"reasons", CertStrings(gate, "reasons")},
                {"missing", CertStrings(gate, "missing")},
                {"notes", CertStrings(gate, "notes")},
                {"override", c.value("override", Json())}}},
              {"fit",
               {{"chi2", CertNumber(CertNumberOr(fit_source, "chi2", NAN))},
                {"dof", CertNumber(CertNumberOr(fit_source, "dof", NAN))},
                {"p_value", CertNumber(CertNumberOr(fit_source, "p_value", NAN))},
                {"rank", CertNumber(CertNumberOr(fit_source, "rank", NAN))},
                {"parameters", thermal ? fitted : parameters.size()},
                {"gauge", CertString(c, "gauge")},
                {"message", CertString(c.value("fit_check", Json()), "message")}}},
              {"renderer", std::string("turncal ") + kVersion}};
  if (thermal) (*content)["temperature"] = temperature;
  if (nlohmann::json drift = DriftSummary(source.drift, model); !drift.is_null())
    (*content)["drift"] = drift;
  return true;
}

}  // namespace turncal::report
