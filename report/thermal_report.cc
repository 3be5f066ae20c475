#include "report/thermal_report.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>

#include "core/estimation/thermal_calibrator.h"
#include "protocol/calibration_json.h"
#include "protocol/sequencer_json.h"
#include "protocol/thermal_json.h"
#include "report/svg.h"

namespace turncal::report {
namespace {

using svg::Escape;
using svg::Num;

constexpr int kCurvePoints = 41;

// One small panel: the parameter (in its display unit) against temperature with its 1 sigma
// band, and the poses' temperatures as ticks along the bottom.
std::string ParameterPanel(const ParameterInfo& p, int j, const ThermalEstimate& e,
                           const std::vector<double>& pose_temps, double x, double y, double w,
                           double h) {
  std::vector<double> t, v, s;
  for (int i = 0; i < kCurvePoints; ++i) {
    const double temp = e.t_min_c + (e.t_max_c - e.t_min_c) * i / (kCurvePoints - 1);
    t.push_back(temp);
    v.push_back(ForDisplay(p, e.ThetaAt(temp)[j], false).value);
    s.push_back(ForDisplay(p, e.SigmaAt(temp)[j], true).value);
  }
  double lo = 1e300, hi = -1e300;
  for (std::size_t i = 0; i < t.size(); ++i) {
    if (!std::isfinite(v[i]) || !std::isfinite(s[i])) continue;
    lo = std::min(lo, v[i] - s[i]);
    hi = std::max(hi, v[i] + s[i]);
  }
  if (!(lo <= hi)) lo = -1, hi = 1;
  double t_lo = e.t_min_c, t_hi = e.t_max_c;
  svg::PadRange(&lo, &hi, false);
  svg::PadRange(&t_lo, &t_hi, false);
  const svg::Panel panel = svg::MakePanel(x, y, w, h, t_lo, t_hi, lo, hi, false);
  std::string o;
  const DisplayQuantity unit = ForDisplay(p, 0.0, false);
  svg::DrawAxes(panel,
                fmt::format("{} (order {})", p.name, e.basis.orders[static_cast<std::size_t>(j)]),
                "degC", unit.unit, &o);
  std::string band, line;
  for (std::size_t i = 0; i < t.size(); ++i) {
    band += fmt::format("{},{} ", Num(panel.sx(t[i])), Num(panel.sy(v[i] + s[i])));
    line += fmt::format("{},{} ", Num(panel.sx(t[i])), Num(panel.sy(v[i])));
  }
  for (std::size_t i = t.size(); i-- > 0;) {
    band += fmt::format("{},{} ", Num(panel.sx(t[i])), Num(panel.sy(v[i] - s[i])));
  }
  o += fmt::format(
      R"(<g class="thermal-parameter" data-parameter="{}"><polygon class="band" points="{}" fill="{}" fill-opacity="0.25" stroke="none"><title>1 sigma</title></polygon>)",
      Escape(p.name), band, svg::Color(0));
  o += fmt::format(R"(<polyline points="{}" fill="none" stroke="{}" stroke-width="1.5"/>)", line,
                   svg::Color(0));
  for (double pt : pose_temps) {
    o += fmt::format(
        R"(<line class="pose-temp" x1="{0}" x2="{0}" y1="{1}" y2="{2}" stroke="#888"/>)",
        Num(panel.sx(pt)), Num(panel.y + panel.h), Num(panel.y + panel.h - 5));
  }
  o += "</g>\n";
  return o;
}

// Each pose's residual (the mean measured minus the model's prediction with the parameters at the
// pose's temperature), per axis, against the pose's temperature.
std::string ResidualPanel(const MeasurementModel& model, const ThermalEstimate& e,
                          const std::vector<PoseRecord>& records, double x, double y, double w,
                          double h, int* shown) {
  std::vector<std::array<double, 4>> points;  // T, rx, ry, rz
  for (const PoseRecord& r : records) {
    const TriadStats* stats = TriadFor(model.sensor(), r);
    if (!stats || !r.temp_c || r.pose.is_rate()) continue;
    const Eigen::Vector3d res = stats->mean - model.Predict(e.ThetaAt(*r.temp_c), r.pose);
    points.push_back({*r.temp_c, res.x(), res.y(), res.z()});
  }
  *shown = static_cast<int>(points.size());
  double lo = 0, hi = 0;
  for (const auto& p : points) {
    for (int a = 1; a < 4; ++a) lo = std::min(lo, p[a]), hi = std::max(hi, p[a]);
  }
  double t_lo = e.t_min_c, t_hi = e.t_max_c;
  svg::PadRange(&lo, &hi, true);
  svg::PadRange(&t_lo, &t_hi, false);
  const svg::Panel panel = svg::MakePanel(x, y, w, h, t_lo, t_hi, lo, hi, false);
  std::string o;
  svg::DrawAxes(panel, "residuals (measured - model at the pose's temperature)", "degC",
                model.sensor() == SensorKind::kAccelerometer ? "m/s^2"
                : model.sensor() == SensorKind::kGyroscope   ? "rad/s"
                                                             : "device unit",
                &o);
  const char* axes[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    o += fmt::format(R"(<g class="thermal-residuals" data-axis="{}" fill="{}">)", axes[a],
                     svg::Color(a + 1));
    for (const auto& p : points) {
      o += fmt::format(R"(<circle cx="{}" cy="{}" r="2"/>)", Num(panel.sx(p[0])),
                       Num(panel.sy(p[static_cast<std::size_t>(a) + 1])));
    }
    o += "</g>\n";
  }
  return o;
}

}  // namespace

bool ThermalSectionHtml(const nlohmann::json& doc, std::string* html, std::string* error) {
  const std::string name = doc.value("model", "");
  const std::string base = doc.value("base_model", "");
  ModelContext context;
  if (doc.contains("context") && !protocol::ParseModelContext(doc["context"], &context, error)) {
    return false;
  }
  const auto model = MakeModel(base, context, error);
  if (!model) return false;
  ThermalEstimate e;
  std::string why;
  if (!protocol::ReadThermalEstimate(*model, doc, &e, &why)) {
    *error = name + ": " + why;
    return false;
  }
  std::vector<PoseRecord> records;
  std::vector<double> pose_temps;
  const nlohmann::json& provenance = doc.value("provenance", nlohmann::json::object());
  for (const auto& j : provenance.value("records", nlohmann::json::array())) {
    PoseRecord r;
    if (!protocol::ParsePoseRecord(j, &r, &why)) continue;
    if (r.temp_c) pose_temps.push_back(*r.temp_c);
    records.push_back(std::move(r));
  }
  const nlohmann::json& t = doc["temperature"];
  std::string o = fmt::format(
      "<section class=\"thermal\" id=\"thermal-{0}\"><h2>{0}: over temperature</h2>\n<p>Version "
      "{1}, calibrated from {2:.1f} to {3:.1f} degC ({4} poses at {5} temperatures), each "
      "parameter a polynomial in (T - {6:.1f} degC) of its own order; chi2/dof = {7:.1f}/{8}, p = "
      "{9:.3g}. Outside the range turncald clamps to the nearer end and flags the sample.</p>\n",
      Escape(name), doc.value("version", 0), e.t_min_c, e.t_max_c, t.value("poses", 0),
      t.value("distinct_temperatures", 0), e.basis.t0_c, t.value("chi2", 0.0), t.value("dof", 0),
      t.value("p_value", 1.0));
  // The table: each parameter at the range's ends and at t0, with its 1 sigma.
  o += "<table><tr><th>parameter</th><th>order</th>";
  const double at[3] = {e.t_min_c, e.basis.t0_c, e.t_max_c};
  for (double temp : at) o += fmt::format("<th>at {:.1f} degC</th>", temp);
  o += "</tr>\n";
  const auto& params = model->parameters();
  for (std::size_t j = 0; j < params.size(); ++j) {
    o += fmt::format("<tr><td>{}</td><td>{}</td>", Escape(params[j].name), e.basis.orders[j]);
    for (double temp : at) {
      const DisplayQuantity value =
          ForDisplay(params[j], e.ThetaAt(temp)[static_cast<Eigen::Index>(j)], false);
      o += fmt::format(
          "<td>{:.6g} {} &plusmn; {}</td>", value.value, value.unit,
          Escape(FormatSigma(params[j], e.SigmaAt(temp)[static_cast<Eigen::Index>(j)])));
    }
    o += "</tr>\n";
  }
  o += "</table>\n";
  // The plots: every parameter that depends on temperature, then the residuals.
  std::vector<int> varying;
  for (std::size_t j = 0; j < params.size(); ++j) {
    if (e.basis.orders[j] > 0) varying.push_back(static_cast<int>(j));
  }
  const int per_row = 4;
  const double pw = 170, ph = 110, gap_x = 55, gap_y = 60, left = 60, top = 40;
  const int rows = (static_cast<int>(varying.size()) + per_row - 1) / per_row;
  const double width = left + per_row * (pw + gap_x);
  const double height = top + rows * (ph + gap_y) + 240;
  std::string plot = svg::Open(
      "thermal-" + name, width, height, name + " against temperature",
      "Each temperature-dependent parameter against the sensor's temperature over the calibrated "
      "range with its 1 sigma band (ticks: the poses' temperatures), and the poses' residuals "
      "against temperature.");
  for (std::size_t k = 0; k < varying.size(); ++k) {
    const int j = varying[k];
    const double x = left + static_cast<double>(k % per_row) * (pw + gap_x);
    const double y = top + static_cast<double>(k / per_row) * (ph + gap_y);
    plot += ParameterPanel(params[static_cast<std::size_t>(j)], j, e, pose_temps, x, y, pw, ph);
  }
  int shown = 0;
  plot += ResidualPanel(*model, e, records, left, top + rows * (ph + gap_y) + 20, width - left - 40,
                        170, &shown);
  plot += svg::Close();
  o += plot;
  if (varying.empty()) o += "<p>No parameter depends on temperature at this precision.</p>\n";
  o += fmt::format(
      "<p class=\"small\">Residuals of {} static poses (rate segments are not shown); "
      "x, y, z in the palette's second, third and fourth colours.</p>\n</section>\n",
      shown);
  *html = std::move(o);
  return true;
}

}  // namespace turncal::report
