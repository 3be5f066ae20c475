// `turncal registry drift SERIAL` (issue 39 item 3; docs/REGISTRY.md "Drift"): each parameter's
// history over the unit's passing calibrations, its turn-on-to-turn-on repeatability (sessions on
// the same day), its trend per month with a sigma, and the date the trend takes it outside its
// tolerance (core/analysis/parameter_drift.h).

#include <fmt/format.h>

#include <cmath>
#include <ctime>
#include <map>

#include "core/analysis/parameter_drift.h"
#include "tools/registry_common.h"

namespace turncal::tools {

namespace {

using daemon::RegistryDb;
using daemon::RegistryRows;

// One calibration a session: a session re-estimates and publishes several versions; its last
// one counts (sessions are told apart by their batch, every session's since schema version 4;
// older calibrations count each).
constexpr const char* kDriftSql = R"sql(
SELECT * FROM (
  SELECT DISTINCT ON (c.model, c.station_id, COALESCE(c.batch_id::text, c.id::text))
    c.model, extract(epoch FROM c.calibrated_at)::double precision AS t_s, c.calibrated_at,
    s.name AS station, c.version, c.parameters, c.tolerances
  FROM calibrations c JOIN devices d ON d.id = c.device_id JOIN stations s ON s.id = c.station_id
  WHERE d.serial = $1 AND ($2::text IS NULL OR c.model = $2) AND c.passed
  ORDER BY c.model, c.station_id, COALESCE(c.batch_id::text, c.id::text), c.version DESC,
    c.calibrated_at DESC, c.id DESC
) sessions ORDER BY model, t_s)sql";

std::string Date(double t_s) {
  if (!std::isfinite(t_s)) return "-";
  const std::time_t t = static_cast<std::time_t>(t_s);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[16];
  std::strftime(buf, sizeof buf, "%Y-%m-%d", &tm);
  return buf;
}

struct DriftArgs {
  std::shared_ptr<RegistryArgs> registry = std::make_shared<RegistryArgs>();
  std::vector<std::string> tolerances;  // NAME=VALUE
};

nlohmann::json DriftJson(const std::string& model, const std::string& name, const ParameterDrift& d,
                         const std::vector<DriftPoint>& points) {
  nlohmann::json history = nlohmann::json::array();
  for (const DriftPoint& p : points)
    history.push_back({{"t", Date(p.t_s)}, {"t_s", p.t_s}, {"value", p.value}, {"sigma", p.sigma}});
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); };
  nlohmann::json j = {{"model", model},
                      {"parameter", name},
                      {"calibrations", d.calibrations},
                      {"history", history}};
  if (!d.ok) {
    j["error"] = d.error;
    return j;
  }
  j["first"] = Date(d.first_t_s);
  j["last"] = Date(d.last_t_s);
  j["repeatability"] = {{"value", num(d.repeatability)},
                        {"ci95", {num(d.repeatability_low95), num(d.repeatability_high95)}},
                        {"beyond_calibration_sigma", num(d.repeatability_beyond)},
                        {"same_day_groups", d.repeat_groups},
                        {"dof", d.repeat_dof}};
  j["trend"] = {{"per_month", d.PerMonth(d.slope_per_s)},
                {"sigma_per_month", d.PerMonth(d.slope_sigma_per_s)},
                {"resolved", d.trend_resolved},
                {"value_at_last", d.value_at_last},
                {"value_at_last_sigma", d.value_at_last_sigma},
                {"wander", d.wander},
                {"chi2", d.chi2},
                {"dof", d.dof}};
  j["tolerance"] = num(d.tolerance);
  j["recalibrate"] =
      d.has_recalibration
          ? nlohmann::json{{"date", Date(d.recalibrate_t_s)},
                           {"t_s", d.recalibrate_t_s},
                           {"sigma_days", d.recalibrate_sigma_s / 86400.0},
                           {"not_before", Date(d.not_before_t_s)}}
          : nlohmann::json{{"date", nullptr}, {"not_before", Date(d.not_before_t_s)}};
  return j;
}

}  // namespace

// Every parameter's drift of `serial` (one model, or every one when `model` is empty): the rows
// `--json` prints, and the table's text. False with the message when the query fails; an empty
// list when the serial has no passing calibration.
bool AnalyseSerialDrift(RegistryDb* db, const std::string& serial, const std::string& model_only,
                        const std::map<std::string, double>& override_tolerance,
                        nlohmann::json* out, std::string* text, std::string* error) {
  RegistryRows rows;
  if (!db->Query(kDriftSql, {serial, Maybe(model_only)}, &rows, error)) return false;
  const nlohmann::json list = RowsJson(rows);
  *out = nlohmann::json::array();
  // model -> parameter -> history, in time order; and the latest tolerance of each.
  std::map<std::string, std::map<std::string, std::vector<DriftPoint>>> histories;
  std::map<std::string, std::map<std::string, double>> tolerances;
  for (const auto& c : list) {
    const std::string model = c.value("model", "");
    const double t = c["t_s"].is_number() ? c["t_s"].get<double>() : NAN;
    if (!c["parameters"].is_object()) continue;
    for (const auto& [name, p] : c["parameters"].items()) {
      if (!p.is_object() || !p["value"].is_number()) continue;
      const double sigma =
          p.contains("sigma") && p["sigma"].is_number() ? p["sigma"].get<double>() : 0.0;
      histories[model][name].push_back({t, p["value"].get<double>(), sigma});
    }
    if (c["tolerances"].is_object()) {
      for (const auto& [name, v] : c["tolerances"].items())
        if (v.is_number()) tolerances[model][name] = v.get<double>();
    }
  }
  for (const auto& [model, params] : histories) {
    if (text) {
      *text += fmt::format("\n{} ({} calibrations, one a session):\n", model,
                           params.begin()->second.size());
      *text += fmt::format("{:<10} {:>13} {:>22} {:>22} {:>11} {:>12} {:>12}\n", "parameter",
                           "latest", "repeatability (95 %)", "trend / month", "tolerance",
                           "recalibrate", "not before");
    }
    for (const auto& [name, points] : params) {
      double tolerance = NAN;
      if (auto it = override_tolerance.find(name); it != override_tolerance.end()) {
        tolerance = it->second;
      } else if (auto m = tolerances.find(model); m != tolerances.end()) {
        if (auto t = m->second.find(name); t != m->second.end()) tolerance = t->second;
      }
      const ParameterDrift d = AnalyseParameterDrift(points, tolerance);
      out->push_back(DriftJson(model, name, d, points));
      if (!text) continue;
      if (!d.ok) {
        *text += fmt::format("{:<10} {}\n", name, d.error);
        continue;
      }
      const std::string repeat = std::isfinite(d.repeatability)
                                     ? fmt::format("{:.3g} ({:.2g}-{:.2g})", d.repeatability,
                                                   d.repeatability_low95, d.repeatability_high95)
                                     : "no same-day pair";
      const std::string trend =
          fmt::format("{:+.3g} +- {:.2g}{}", d.PerMonth(d.slope_per_s),
                      d.PerMonth(d.slope_sigma_per_s), d.trend_resolved ? "" : " (none)");
      const std::string recal = d.has_recalibration
                                    ? fmt::format("{} +- {:.0f} d", Date(d.recalibrate_t_s),
                                                  d.recalibrate_sigma_s / 86400)
                                    : "-";
      *text += fmt::format("{:<10} {:>13.6g} {:>22} {:>22} {:>11} {:>12} {:>12}\n", name,
                           points.back().value, repeat, trend,
                           std::isfinite(tolerance) ? fmt::format("{:.3g}", tolerance) : "-", recal,
                           Date(d.not_before_t_s));
    }
  }
  return true;
}

namespace {

int RunDrift(const DriftArgs& args) {
  const RegistryArgs& a = *args.registry;
  std::map<std::string, double> override_tolerance;
  for (const std::string& t : args.tolerances) {
    const auto eq = t.find('=');
    char* end = nullptr;
    const double v = eq == std::string::npos ? NAN : std::strtod(t.c_str() + eq + 1, &end);
    if (eq == std::string::npos || end == t.c_str() + eq + 1 || *end != '\0' || !(v > 0)) {
      fmt::print(stderr, "turncal registry drift: --tolerance '{}' is not NAME=VALUE (> 0)\n", t);
      return 2;
    }
    override_tolerance[t.substr(0, eq)] = v;
  }
  RegistryDb db;
  if (int rc = OpenRegistry(a, &db)) return rc;
  nlohmann::json out;
  std::string text, error;
  if (!AnalyseSerialDrift(&db, a.serial, a.model, override_tolerance, &out, &text, &error)) {
    fmt::print(stderr, "turncal registry: {}\n", error);
    return 2;
  }
  if (out.empty()) {
    fmt::print(stderr, "turncal registry drift: serial {} has no passing calibration{}\n", a.serial,
               a.model.empty() ? "" : " of " + a.model);
    return 1;
  }
  if (a.json) return Emit(a, out.dump(1) + "\n");
  return Emit(
      a, fmt::format("serial {}: each parameter over its passing calibrations (one a session). "
                     "Repeatability: the pooled scatter of calibrations on the same day (turn-on "
                     "to turn-on). Trend: a weighted line in time (weights: the calibration's "
                     "sigma and the wander beyond it). Recalibrate: when the trend will have moved "
                     "the parameter by its tolerance since the last calibration (the gate's, or "
                     "--tolerance); 'not before': the 95 % bound of that date.{}",
                     a.serial, text));
}

}  // namespace

void AddRegistryDriftCommand(CLI::App* registry) {
  auto args = std::make_shared<DriftArgs>();
  CLI::App* d = registry->add_subcommand(
      "drift",
      "a serial's parameters over its calibrations: repeatability, trend per month, the "
      "recalibration date (issue 39)");
  d->add_option("SERIAL", args->registry->serial, "the device's serial")->required();
  d->add_option("--model", args->registry->model, "only this model");
  d->add_option("--tolerance", args->tolerances,
                "NAME=VALUE: the parameter's tolerance for the recalibration date (default: the "
                "gate's tolerance the calibration records)");
  d->add_flag("--json", args->registry->json, "as JSON, with every parameter's history");
  d->add_option("-o,--output", args->registry->output, "write here (atomically) instead of stdout");
  AddConnectionOptions(d, args->registry);
  d->callback([args] { throw CLI::RuntimeError(RunDrift(*args)); });
}

}  // namespace turncal::tools
