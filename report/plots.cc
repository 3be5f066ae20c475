#include "report/plots.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/frames/reference.h"
#include "report/svg.h"

namespace turncal::report {
namespace {

using svg::Escape;
using svg::Num;

constexpr const char* kAxisNames[] = {"x", "y", "z"};
constexpr const char* kAxisColors[] = {"#1f77b4", "#2ca02c", "#d62728"};

// A plot that cannot be drawn: the frame with the reason, so the document keeps every plot id.
std::string Missing(const std::string& id, const std::string& title, const std::string& why) {
  std::string o = svg::Open(id, 900, 80, title, why);
  o += fmt::format(R"(<text class="missing" x="20" y="45">{}: {}</text>)", Escape(title),
                   Escape(why));
  return o + svg::Close();
}

std::string SensorWord(const MeasurementModel& model) { return ToString(model.sensor()); }

// The range of finite positive values, out to whole decades (including 1 when asked).
bool DecadeRange(const std::vector<double>& values, bool with_one, double* lo, double* hi) {
  double mn = INFINITY, mx = 0;
  for (double v : values) {
    if (std::isfinite(v) && v > 0) {
      mn = std::min(mn, v);
      mx = std::max(mx, v);
    }
  }
  if (!(mx > 0)) return false;
  if (with_one) {
    mn = std::min(mn, 1.0);
    mx = std::max(mx, 1.0);
  }
  *lo = std::pow(10.0, std::floor(std::log10(mn)));
  // Strictly above the largest value, so that a line at 1 is not drawn on the frame.
  *hi = std::pow(10.0, std::floor(std::log10(mx)) + 1);
  return true;
}

}  // namespace

ResidualUnit ResidualUnitFor(const MeasurementModel& model) {
  if (model.sensor() == SensorKind::kAccelerometer) return {1e3 / kStandardGravity_mps2, "mg"};
  if (model.sensor() == SensorKind::kGyroscope) return {180 / M_PI * 3600, "deg/h"};
  return {1e3, "mG"};
}

std::string ResidualsSvg(const protocol::CalibrationDocument& doc, const ModelAnalysis& a) {
  const std::string id = "residuals-" + doc.model;
  const MeasurementModel& model = *doc.measurement_model;
  const std::string title = fmt::format("{} residuals per pose before and after calibration ({})",
                                        doc.model, SensorWord(model));
  if (!a.has_records) return Missing(id, title, a.no_records_reason);
  const PoseResiduals& r = a.residuals;
  const ResidualUnit unit = ResidualUnitFor(model);
  const auto n = static_cast<double>(r.after.size());
  // The x axis is time since the first pose when the records carry their windows (a trend with
  // time is drift the noise model does not carry, issue 19), else the pose number.
  std::vector<double> xs;
  bool timed = true;
  for (std::size_t i = 0; i < r.after.size() && timed; ++i) {
    const auto k = static_cast<std::size_t>(r.pose_index[i]);
    timed = k < doc.records.size() && doc.records[k].t_end_s > doc.records[k].t_start_s;
    if (timed) xs.push_back(0.5 * (doc.records[k].t_start_s + doc.records[k].t_end_s));
  }
  if (!timed || xs.empty()) {
    xs.clear();
    for (std::size_t i = 0; i < r.after.size(); ++i) xs.push_back(static_cast<double>(i) + 1);
  } else {
    const double t0 = *std::min_element(xs.begin(), xs.end());
    for (double& x : xs) x -= t0;
  }
  const double x_max = xs.empty() ? 1.0 : *std::max_element(xs.begin(), xs.end());
  const double x_pad = timed ? std::max(1.0, 0.03 * x_max) : 0.5;
  const double x_lo = timed ? -x_pad : 0.5, x_hi = timed ? x_max + x_pad : n + 0.5;
  const double width = 900, height = 505, left = 70, panel_w = 230, gap_x = 60, panel_h = 150;
  std::string o = svg::Open(
      id, width, height, title,
      fmt::format("Measured mean minus the model's prediction at each of {} poses, per sensor "
                  "axis, in {}, against {}: top row at the nominal parameters, bottom row at the "
                  "estimate with each pose mean's 1 sigma.",
                  r.after.size(), unit.name,
                  timed ? "the time since the first pose" : "the pose number"));
  o += fmt::format(R"(<text class="plot-title" x="{}" y="20">{}</text>)", Num(left), Escape(title));
  for (int row = 0; row < 2; ++row) {
    const bool after = row == 1;
    const auto& values = after ? r.after : r.before;
    const Eigen::Vector3d& rms = after ? r.rms_after : r.rms_before;
    for (int axis = 0; axis < 3; ++axis) {
      double lo = INFINITY, hi = -INFINITY;
      for (std::size_t i = 0; i < values.size(); ++i) {
        double v = values[i][axis] * unit.per_triad_unit;
        double s =
            after && i < r.sigma_mean.size() ? r.sigma_mean[i][axis] * unit.per_triad_unit : 0.0;
        lo = std::min(lo, v - s);
        hi = std::max(hi, v + s);
      }
      svg::PadRange(&lo, &hi, /*with_zero=*/true);
      const double x = left + axis * (panel_w + gap_x);
      const double y = 60 + row * (panel_h + 70);
      const svg::Panel p = svg::MakePanel(x, y, panel_w, panel_h, x_lo, x_hi, lo, hi, false);
      svg::DrawAxes(
          p,
          fmt::format("{} {}: RMS {:.3g} {}", kAxisNames[axis], after ? "after" : "before",
                      rms[axis] * unit.per_triad_unit, unit.name),
          timed ? "time since the first pose, s" : "pose",
          axis == 0 ? fmt::format("residual, {}", unit.name) : "", &o);
      o += fmt::format(R"(<line class="zero" x1="{}" y1="{}" x2="{}" y2="{}"/>)", Num(p.x),
                       Num(p.sy(0)), Num(p.x + p.w), Num(p.sy(0)));
      o += fmt::format(R"(<g class="{}" fill="{}" stroke="{}">)",
                       after ? "residual-after" : "residual-before", kAxisColors[axis],
                       kAxisColors[axis]);
      for (std::size_t i = 0; i < values.size(); ++i) {
        const double px = p.sx(xs[i]);
        const double v = values[i][axis] * unit.per_triad_unit;
        if (after && i < r.sigma_mean.size()) {
          const double s = r.sigma_mean[i][axis] * unit.per_triad_unit;
          o += fmt::format(R"(<line x1="{0}" y1="{1}" x2="{0}" y2="{2}"/>)", Num(px),
                           Num(p.sy(v - s)), Num(p.sy(v + s)));
        }
        o += fmt::format(
            R"(<circle cx="{}" cy="{}" r="2.5"><title>pose {}: {:.4g} {}</title></circle>)",
            Num(px), Num(p.sy(v)), r.pose_index[i] + 1, v, unit.name);
      }
      o += "</g>";
    }
  }
  o += fmt::format(
      R"(<text class="note" x="{}" y="{}">Residual RMS over the three axes: {:.4g} {} before, {:.4g} {} after (a factor {:.3g}).</text>)",
      Num(left), Num(height - 12), r.rms_before_total * unit.per_triad_unit, unit.name,
      r.rms_after_total * unit.per_triad_unit, unit.name,
      r.rms_after_total > 0 ? r.rms_before_total / r.rms_after_total : INFINITY);
  return o + svg::Close();
}

std::string CoverageSvg(const protocol::CalibrationDocument& doc, const ModelAnalysis& a) {
  const std::string id = "coverage-" + doc.model;
  const SensorKind kind = doc.measurement_model->sensor();
  const std::string vector_name = kind == SensorKind::kAccelerometer ? "gravity g"
                                  : kind == SensorKind::kGyroscope
                                      ? "the inertial rate (rate segments' axes, the Earth's rate)"
                                      : "the Earth field B";
  const std::string title =
      fmt::format("{} pose coverage: {} in the sensor frame", doc.model, vector_name);
  if (a.reference_dir_sensor.empty()) {
    return Missing(id, title, "the calibration lists no poses");
  }
  const double width = 680, height = 400, radius = 140;
  const double cx[2] = {180, 500}, cy = 200;
  std::string o = svg::Open(
      id, width, height, title,
      fmt::format("Direction of {} in the sensor's nominal case frame at each of {} poses, "
                  "orthographic projection onto the x-y plane seen from +z: left the hemisphere "
                  "z >= 0, right z < 0. Circles at 30 and 60 degrees from the x-y plane; "
                  "numbers are pose numbers, colour runs from the first pose (blue) to the last "
                  "(red).",
                  vector_name, a.reference_dir_sensor.size()));
  o += fmt::format(R"(<text class="plot-title" x="20" y="24">{}</text>)", Escape(title));
  int counts[2] = {0, 0};
  for (const auto& d : a.reference_dir_sensor) ++counts[d.z() >= 0 ? 0 : 1];
  for (int h = 0; h < 2; ++h) {
    o += fmt::format(R"(<circle class="frame" cx="{}" cy="{}" r="{}"/>)", Num(cx[h]), Num(cy),
                     Num(radius));
    for (double elevation_deg : {30.0, 60.0}) {
      o += fmt::format(R"(<circle class="grid" cx="{}" cy="{}" r="{}"/>)", Num(cx[h]), Num(cy),
                       Num(radius * std::cos(elevation_deg * M_PI / 180)));
    }
    o += fmt::format(R"(<line class="grid" x1="{0}" y1="{1}" x2="{2}" y2="{1}"/>)",
                     Num(cx[h] - radius), Num(cy), Num(cx[h] + radius));
    o += fmt::format(R"(<line class="grid" x1="{0}" y1="{1}" x2="{0}" y2="{2}"/>)", Num(cx[h]),
                     Num(cy - radius), Num(cy + radius));
    o += fmt::format(R"(<text class="tick" x="{}" y="{}">+x</text>)", Num(cx[h] + radius + 4),
                     Num(cy + 4));
    o += fmt::format(R"(<text class="tick" x="{}" y="{}" text-anchor="middle">+y</text>)",
                     Num(cx[h]), Num(cy - radius - 6));
    o += fmt::format(
        R"(<text class="panel-title" x="{}" y="{}" text-anchor="middle">{} ({} poses)</text>)",
        Num(cx[h]), Num(cy + radius + 24),
        Escape(h == 0 ? "z >= 0 (toward +z)" : "z < 0 (toward -z)"), counts[h]);
  }
  const std::size_t n = a.reference_dir_sensor.size();
  o += R"(<g class="pose-directions">)";
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d& d = a.reference_dir_sensor[i];
    const int h = d.z() >= 0 ? 0 : 1;
    const double px = cx[h] + radius * d.x(), py = cy - radius * d.y();
    const double hue = n > 1 ? 240.0 * (1.0 - static_cast<double>(i) / (n - 1)) : 240.0;
    o += fmt::format(
        R"~(<circle cx="{}" cy="{}" r="4" fill="hsl({:.0f},80%,45%)"><title>pose {}: ({:+.3f}, {:+.3f}, {:+.3f})</title></circle>)~",
        Num(px), Num(py), hue, i + 1, d.x(), d.y(), d.z());
    o += fmt::format(R"(<text class="point-label" x="{}" y="{}">{}</text>)", Num(px + 5),
                     Num(py - 4), i + 1);
  }
  o += "</g>";
  return o + svg::Close();
}

std::string ConvergenceSvg(const protocol::CalibrationDocument& doc, const ModelAnalysis& a) {
  const std::string id = "convergence-" + doc.model;
  const MeasurementModel& model = *doc.measurement_model;
  const std::string title = fmt::format("{} convergence: sigma as poses were added", doc.model);
  const Convergence& c = a.convergence;
  if (c.k.empty()) {
    return Missing(id, title, c.note.empty() ? "too few poses to solve" : c.note);
  }
  const auto& params = model.parameters();
  const int N = model.num_parameters();
  // Gated parameters against their tolerance; the others against their sigma with every pose.
  std::vector<int> gated, other;
  for (int j = 0; j < N; ++j) {
    (doc.tolerances.count(params[static_cast<std::size_t>(j)].name) ? gated : other).push_back(j);
  }
  const Eigen::VectorXd& final_sigma = c.sigma.back();
  auto ratio = [&](std::size_t step, int j) {
    const double s = c.sigma[step][j];
    const auto it = doc.tolerances.find(params[static_cast<std::size_t>(j)].name);
    const double ref = it != doc.tolerances.end() ? it->second : final_sigma[j];
    return std::isfinite(s) && std::isfinite(ref) && ref > 0 ? s / ref : std::nan("");
  };
  const double width = 900, top = 60, panel_h = 260, left = 70;
  const int per_row = 6;
  const int legend_rows = (N + per_row - 1) / per_row;
  const double height = top + panel_h + 60 + 20.0 * legend_rows + 20;
  std::string o = svg::Open(
      id, width, height, title,
      fmt::format("Each parameter's 1 sigma after the first k poses (the calibrator re-solved "
                  "pose by pose, k = {} to {}), log scale: left the gated parameters divided by "
                  "their tolerance (the gate needs at most 1), right the others divided by their "
                  "sigma with every pose.",
                  c.k.front(), c.k.back()));
  o += fmt::format(R"(<text class="plot-title" x="{}" y="20">{}</text>)", Num(left), Escape(title));
  const std::vector<int>* groups[2] = {&gated, &other};
  const int panels = other.empty() || gated.empty() ? 1 : 2;
  const double panel_w = panels == 1 ? 800 : 360;
  int drawn = 0;
  for (int g = 0; g < 2; ++g) {
    const std::vector<int>& group = *groups[g];
    if (group.empty()) continue;
    std::vector<double> values;
    for (std::size_t s = 0; s < c.k.size(); ++s)
      for (int j : group) values.push_back(ratio(s, j));
    double lo = 0.1, hi = 10;
    DecadeRange(values, /*with_one=*/true, &lo, &hi);
    const double x = left + drawn * (panel_w + 100);
    ++drawn;
    const double k_lo = c.k.front() - 0.5, k_hi = c.k.back() + 0.5;
    const svg::Panel p = svg::MakePanel(x, top, panel_w, panel_h, k_lo, k_hi, lo, hi, true);
    svg::DrawAxes(p, g == 0 ? "gated: sigma / tolerance" : "not gated: sigma / final sigma",
                  "poses used", g == 0 ? "sigma / tolerance" : "sigma / final sigma", &o);
    if (g == 0) {
      o += fmt::format(
          R"(<line class="tolerance" x1="{0}" y1="{1}" x2="{2}" y2="{1}"><title>tolerance</title></line>)",
          Num(p.x), Num(p.sy(1.0)), Num(p.x + p.w));
    }
    for (int j : group) {
      const std::string& name = params[static_cast<std::size_t>(j)].name;
      o += fmt::format(
          R"(<g class="sigma-series" data-parameter="{}" stroke="{}" stroke-dasharray="{}"><title>{}</title>)",
          Escape(name), svg::Color(j), svg::Dash(j), Escape(name));
      std::string points;
      auto flush = [&] {
        if (!points.empty()) o += "<polyline points=\"" + points + "\"/>";
        points.clear();
      };
      for (std::size_t s = 0; s < c.k.size(); ++s) {
        const double v = ratio(s, j);
        if (!p.sy.Contains(v)) {
          flush();
          continue;
        }
        points += (points.empty() ? "" : " ") + Num(p.sx(c.k[s])) + "," + Num(p.sy(v));
      }
      flush();
      o += "</g>";
    }
  }
  // Legend: every parameter's colour and dash.
  const double legend_y = top + panel_h + 55;
  for (int j = 0; j < N; ++j) {
    const double x = left + (j % per_row) * 135, y = legend_y + 20.0 * (j / per_row);
    o += fmt::format(
        R"(<line x1="{}" y1="{}" x2="{}" y2="{}" stroke="{}" stroke-width="2" stroke-dasharray="{}"/>)",
        Num(x), Num(y - 4), Num(x + 24), Num(y - 4), svg::Color(j), svg::Dash(j));
    o += fmt::format(R"(<text class="legend" x="{}" y="{}">{}</text>)", Num(x + 30), Num(y),
                     Escape(params[static_cast<std::size_t>(j)].name));
  }
  return o + svg::Close();
}

}  // namespace turncal::report
