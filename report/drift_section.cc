#include "report/drift_section.h"

#include <fmt/format.h>

#include <cmath>
#include <memory>

#include "core/modeling/measurement_model.h"
#include "report/svg.h"

namespace turncal::report {

nlohmann::json DriftSummary(const nlohmann::json& rows, const std::string& model) {
  if (!rows.is_array()) return nullptr;
  nlohmann::json out = nlohmann::json::array();
  bool any_trend = false;
  for (const auto& r : rows) {
    if (!model.empty() && r.value("model", "") != model) continue;
    nlohmann::json s = r;
    s.erase("history");
    any_trend |= s.contains("trend");
    out.push_back(s);
  }
  return any_trend ? out : nlohmann::json();
}

std::string DriftSectionHtml(const nlohmann::json& summary, const std::string& model) {
  if (!summary.is_array() || summary.empty()) return "";
  std::string error;
  const std::unique_ptr<MeasurementModel> m = MakeModel(model, ModelContext{}, &error);
  // A value in the parameter's report unit (the model's ParameterInfo), or as stored.
  auto shown = [&](const std::string& name, double v) -> std::pair<double, std::string> {
    if (!std::isfinite(v)) return {v, ""};
    if (m) {
      const int i = m->index_of(name);
      if (i >= 0) {
        const DisplayQuantity q =
            ForDisplay(m->parameters()[static_cast<std::size_t>(i)], v, /*is_sigma=*/true);
        return {q.value, q.unit};
      }
    }
    return {v, ""};
  };
  auto num = [](const nlohmann::json& j, const char* key) {
    return j.contains(key) && j[key].is_number() ? j[key].get<double>() : NAN;
  };
  auto value = [](const nlohmann::json& v) { return v.is_number() ? v.get<double>() : NAN; };
  auto fmt_num = [](double v) { return std::isfinite(v) ? fmt::format("{:.3g}", v) : "-"; };
  int calibrations = 0;
  std::string first, last;
  std::string rows;
  for (const auto& r : summary) {
    const std::string name = r.value("parameter", "");
    calibrations = std::max(calibrations, r.value("calibrations", 0));
    if (r.contains("first")) first = r.value("first", "");
    if (r.contains("last")) last = r.value("last", "");
    if (!r.contains("trend")) {
      rows += fmt::format("<tr><td>{}</td><td colspan=\"5\">{}</td></tr>", svg::Escape(name),
                          svg::Escape(r.value("error", "")));
      continue;
    }
    const nlohmann::json& rep = r["repeatability"];
    const nlohmann::json& tr = r["trend"];
    const auto [repeat, unit] = shown(name, num(rep, "value"));
    std::string repeat_cell = "no same-day sessions";
    if (std::isfinite(repeat) && rep["ci95"].is_array()) {
      repeat_cell = fmt::format("{} [{}, {}]", fmt_num(repeat),
                                fmt_num(shown(name, value(rep["ci95"][0])).first),
                                fmt_num(shown(name, value(rep["ci95"][1])).first));
    }
    const double per_month = shown(name, num(tr, "per_month")).first;
    const double per_month_sigma = shown(name, num(tr, "sigma_per_month")).first;
    const std::string trend_cell =
        fmt::format("{:+.3g} &#177; {:.2g}{}", per_month, per_month_sigma,
                    tr.value("resolved", false) ? "" : " (not resolved)");
    const double tolerance = shown(name, num(r, "tolerance")).first;
    const nlohmann::json& recal = r.value("recalibrate", nlohmann::json::object());
    std::string recal_cell = "&#8212;";
    if (recal.contains("date") && recal["date"].is_string()) {
      recal_cell = fmt::format("{} &#177; {:.0f} d", svg::Escape(recal["date"].get<std::string>()),
                               num(recal, "sigma_days"));
    }
    const std::string not_before = recal.contains("not_before") && recal["not_before"].is_string()
                                       ? svg::Escape(recal["not_before"].get<std::string>())
                                       : "-";
    rows += fmt::format(
        "<tr id=\"drift-{}-{}\"><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td>"
        "<td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td>{}</td>"
        "</tr>",
        svg::Escape(model), svg::Escape(name), svg::Escape(name), repeat_cell, trend_cell,
        fmt_num(tolerance), recal_cell, not_before, svg::Escape(unit));
  }
  return fmt::format(
      "<section class=\"drift\"><h2>Drift over the unit's calibrations</h2><p class=\"notes\">"
      "From the registry: {} calibrations of {} (one a session) from {} to {}. Repeatability: "
      "the scatter of sessions on the same day (turn-on to turn-on), its 95 % interval in "
      "brackets. Trend: a weighted line in time per month. Recalibrate: when the trend will "
      "have moved the parameter by its tolerance since the last calibration, &#177; 1&#963;; "
      "not before: its 95 % bound (docs/REGISTRY.md \"Drift\").</p><table class=\"params\">"
      "<thead><tr><th>Parameter</th><th>Repeatability</th><th>Trend / month</th>"
      "<th>Tolerance</th><th>Recalibrate</th><th>Not before</th><th>Unit</th></tr></thead>"
      "<tbody>{}</tbody></table></section>",
      calibrations, svg::Escape(model), svg::Escape(first), svg::Escape(last), rows);
}

}  // namespace turncal::report
