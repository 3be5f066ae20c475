// The IEEE test report's renderings (report/characterisation.h): JSON, HTML and text.

#include <fmt/format.h>

#include <cmath>

#include "report/characterisation.h"
#include "report/svg.h"
#include "turncal/version.h"

namespace turncal::report {
namespace {

using svg::Escape;

std::string Number(double v) {
  if (!std::isfinite(v)) return "-";
  return fmt::format("{:.4g}", v);
}

// The figure and its uncertainty as one cell each: "value", "U" or the interval.
std::pair<std::string, std::string> Cells(const CharacteristicRow& r) {
  if (!r.measured) return {"not measured", ""};
  if (r.upper_bound) {
    // An upper bound of zero: the fit put the term at zero with no room above it.
    if (r.value == 0.0) return {"0", "none seen"};
    return {"< " + Number(r.value), "95 % upper bound"};
  }
  if (r.has_interval) {
    if (r.high95 == 0.0 && r.value == 0.0) return {"0", "none seen"};
    return {Number(r.value), fmt::format("[{}, {}] (95 %)", Number(r.low95), Number(r.high95))};
  }
  return {Number(r.value), Number(r.u95)};
}

constexpr const char* kStyle = R"(
body { font: 14px/1.45 system-ui, sans-serif; color: #222; margin: 24px auto; max-width: 1100px; padding: 0 12px; }
h1 { font-size: 22px; margin-bottom: 4px; } h2 { font-size: 18px; border-bottom: 2px solid #ccc; margin-top: 30px; }
table { border-collapse: collapse; margin: 6px 0; } th, td { padding: 2px 8px; border-bottom: 1px solid #e4e4e4; text-align: left; vertical-align: top; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; } .small, td.from { font-size: 12px; color: #555; }
tr.missing td { color: #999; } tr.missing td.item { color: #a00; }
)";

}  // namespace

nlohmann::json ToJson(const Characterisation& c) {
  nlohmann::json rows = nlohmann::json::array();
  for (const CharacteristicRow& r : c.rows) {
    nlohmann::json j = {{"triad", r.triad}, {"item", r.item},         {"standard", r.standard},
                        {"axis", r.axis},   {"measured", r.measured}, {"from", r.from}};
    if (r.measured) {
      j["value"] = r.value;
      j["unit"] = r.unit;
      if (r.upper_bound) j["upper_bound"] = true;
      if (r.has_interval) {
        j["ci95"] = {r.low95, r.high95};
      } else {
        j["U"] = std::isfinite(r.u95) ? nlohmann::json(r.u95) : nlohmann::json();
      }
    }
    rows.push_back(j);
  }
  return {{"class", "CHARACTERISATION"},
          {"device", c.device},
          {"generated", c.generated_utc},
          {"sources", c.sources},
          {"measured", c.measured()},
          {"not_measured", c.not_measured()},
          {"rows", rows}};
}

std::string CharacterisationHtml(const Characterisation& c) {
  std::string o = "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>";
  o += Escape("IEEE test report" + (c.device.empty() ? "" : ": " + c.device));
  o += "</title><style>" + std::string(kStyle) + "</style></head><body>\n";
  o += "<h1>IEEE test report" + (c.device.empty() ? "" : ": " + Escape(c.device)) + "</h1>\n";
  o += fmt::format(
      "<p class=\"small\">turncal {}{}. {} figures measured, {} items not measured (listed, with "
      "what would measure them). U is the expanded uncertainty, k = 2 (twice the 1 sigma the "
      "fit's Fisher information gives); figures with a skewed or one-sided uncertainty (a "
      "standard deviation, a noise coefficient) show their 95 % interval instead.</p>\n",
      Escape(kVersion), c.generated_utc.empty() ? "" : ", " + Escape(c.generated_utc), c.measured(),
      c.not_measured());
  o += "<ul class=\"small\">";
  for (const std::string& s : c.sources) o += "<li>" + Escape(s) + "</li>";
  o += "</ul>\n";
  for (const char* triad : {"accelerometer", "gyroscope", "magnetometer"}) {
    bool any = false;
    for (const auto& r : c.rows) any |= r.triad == triad;
    if (!any) continue;
    o += fmt::format("<h2 id=\"{}\">{}{}</h2>\n", triad, static_cast<char>(triad[0] - 32),
                     triad + 1);
    o += "<table class=\"characteristics\"><tr><th>Item</th><th>Standard</th><th>Axis</th>"
         "<th>Value</th><th>U (k = 2)</th><th>Unit</th><th>From</th></tr>\n";
    for (const auto& r : c.rows) {
      if (r.triad != triad) continue;
      const auto [value, u] = Cells(r);
      o += fmt::format(
          "<tr class=\"{}\"><td class=\"item\">{}</td><td>{}</td><td>{}</td><td "
          "class=\"num\">{}</td><td class=\"num\">{}</td><td>{}</td><td class=\"from\">{}</td>"
          "</tr>\n",
          r.measured ? "measured" : "missing", Escape(r.item), Escape(r.standard), Escape(r.axis),
          Escape(value), Escape(u), Escape(r.unit), Escape(r.from));
    }
    o += "</table>\n";
  }
  o += "<h2 id=\"not-measured\">Not measured in this session</h2>\n<ul>";
  int listed = 0;
  for (const auto& r : c.rows) {
    if (r.measured) continue;
    o += "<li><strong>" + Escape(r.triad + ": " + r.item) + "</strong> (" + Escape(r.standard) +
         "): " + Escape(r.from) + "</li>";
    ++listed;
  }
  if (listed == 0) o += "<li>nothing: every item the standards ask for was measured</li>";
  o += "</ul>\n</body></html>\n";
  return o;
}

std::string CharacterisationText(const Characterisation& c) {
  std::string o =
      fmt::format("IEEE test report{}: {} figures measured, {} items not measured\n",
                  c.device.empty() ? "" : " of " + c.device, c.measured(), c.not_measured());
  for (const std::string& s : c.sources) o += "  " + s + "\n";
  std::string triad;
  for (const auto& r : c.rows) {
    if (r.triad != triad) {
      triad = r.triad;
      o += fmt::format("\n{}\n{:<52} {:<15} {:>12} {:>26} {}\n", triad, "item", "axis", "value",
                       "U (k = 2)", "unit");
    }
    const auto [value, u] = Cells(r);
    if (!r.measured) {
      o += fmt::format("{:<52} not measured: {}\n", r.item, r.from);
      continue;
    }
    o += fmt::format("{:<52} {:<15} {:>12} {:>26} {}\n", r.item, r.axis, value, u, r.unit);
  }
  return o;
}

}  // namespace turncal::report
