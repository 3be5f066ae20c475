#include "report/free_report.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "protocol/free_json.h"
#include "report/free_sphere.h"
#include "report/svg.h"

namespace turncal::report {
namespace {

const FreeModelResult* UpstreamOf(const FreeReportInput& in, const std::string& model) {
  std::string error;
  auto m = MakeFreeModel(model, in.context, &error);
  if (!m || m->upstream().empty()) return nullptr;
  for (const auto& r : in.results) {
    if (r.model == m->upstream()) return &r;
  }
  return nullptr;
}

// A gap narrower than this is the spacing of a hand's sweeps, not a region left out.
constexpr double kGapWorthSayingDeg = 25.0;

// The unit a misfit kind is shown in, and the factor to it.
std::pair<std::string, double> MisfitUnit(const std::string& kind, SensorKind sensor,
                                          bool relative) {
  if (kind == "direction" || kind == "dip") return {"deg", 180 / M_PI};
  if (kind == "mag norm" || sensor == SensorKind::kMagnetometer) {
    return {relative ? "(relative to the field)" : "(the field's unit)", 1.0};
  }
  return {"m/s^2", 1.0};
}

// "point +x up (the weakest direction's sigma x0.41)"; for a direction the data do not
// determine at all, what the candidate would do for it.
std::string AdviceText(const OrientationAdvice& a) {
  if (!(a.information_before > 1e-12 * std::max(a.information_after, 1e-300))) {
    return a.information_after > 0
               ? a.text + " (it would determine the direction these data leave undetermined)"
               : a.text +
                     " (no single orientation determines what these data leave "
                     "undetermined: add several)";
  }
  return fmt::format("{} (the weakest direction's sigma x{:.2f})", a.text, a.sigma_ratio);
}

std::string Value(double v) { return std::isfinite(v) ? fmt::format("{:.6g}", v) : "inf"; }

SensorKind SensorOf(const FreeReportInput& in, const std::string& model) {
  std::string error;
  auto m = MakeFreeModel(model, in.context, &error);
  return m ? m->sensor() : SensorKind::kAccelerometer;
}

}  // namespace

std::string FreeReportText(const FreeReportInput& in, bool list_intervals) {
  std::string o;
  o += fmt::format("source: {}\n", in.source);
  if (in.found.noise) {
    o += fmt::format("stillness from the noise: {}\n", in.found.noise->Describe());
  } else {
    o += fmt::format(
        "the noise was never measured (the stream was never still for the noise meter's second; "
        "{} attempts{}): no interval can be found\n",
        in.found.noise_retries,
        in.found.last_noise_failure.empty() ? "" : ", the last: " + in.found.last_noise_failure);
  }
  o += fmt::format("{}\n", in.found.summary);
  if (in.motion) o += in.motion->Summary() + "\n";
  if (list_intervals) {
    o += fmt::format("{:>4} {:>9} {:>9} {:>7} {:>8} {:>7}  {}\n", "#", "start s", "end s",
                     "still s", "samples", "move s", "raw mean (acc, else mag, else gyro)");
    for (std::size_t k = 0; k < in.found.intervals.size(); ++k) {
      const FreeInterval& iv = in.found.intervals[k];
      const TriadStats* s = iv.acc ? &*iv.acc : iv.mag ? &*iv.mag : iv.gyr ? &*iv.gyr : nullptr;
      o += fmt::format(
          "{:>4} {:>9.2f} {:>9.2f} {:>7.2f} {:>8} {:>7}  {}\n", k, iv.t_start_s, iv.t_end_s,
          iv.duration_s(), s ? s->count : 0,
          iv.move_in ? fmt::format("{:.2f}", iv.move_in->duration_s()) : "-",
          s ? fmt::format("[{:.4f}, {:.4f}, {:.4f}]", s->mean.x(), s->mean.y(), s->mean.z()) : "");
    }
    for (const auto& why : in.found.skip_reasons) o += fmt::format("  skipped {}\n", why);
  }
  for (std::size_t i = 0; i < in.results.size(); ++i) {
    const FreeModelResult& r = in.results[i];
    const FreeEstimate& fe = r.estimate;
    const Estimate& e = fe.estimate;
    std::string error;
    auto model = MakeFreeModel(r.model, in.context, &error);
    o += fmt::format("\n{}{}\n", r.model, model ? " -- " + model->description() : "");
    if (!r.note.empty()) o += fmt::format("  note: {}\n", r.note);
    if (!e.ok) {
      o += fmt::format("  not fitted: {}\n", e.error);
      continue;
    }
    o += fmt::format(
        "  {} intervals{}, {} residuals; rank {} of {} (condition {:.3g}); chi2/dof {:.2f} (p "
        "{:.2g}{})\n",
        fe.intervals,
        fe.motion_points > 0 ? fmt::format(" ({} of them samples in motion)", fe.motion_points)
                             : "",
        fe.residuals, e.rank, e.parameters.size(), e.condition, e.dof > 0 ? e.chi2 / e.dof : 0.0,
        e.p_value,
        std::isfinite(e.fit.noise_dof)
            ? fmt::format(", the F test against a noise measured with {:.0f} dof, its mean x{:.3f}",
                          e.fit.noise_dof, e.fit.noise_scale)
            : std::string());
    if (e.fit.verdict != FitVerdict::kOk) o += fmt::format("  fit: {}\n", e.fit.cause);
    for (const auto& w : e.warnings) o += fmt::format("  {}\n", w);
    if (const FreeModelResult* up = UpstreamOf(in, r.model)) {
      o += fmt::format("  built on {}'s estimate (its covariance carried into these sigma)\n",
                       up->model);
    }
    if (fe.relative_scale) {
      o += "  the field's magnitude is not known (--field): the soft iron's scale is relative, "
           "|h| = 1\n";
    }
    o += fmt::format("  {:<8} {:>14} {:>12}\n", "", "value", "1 sigma");
    for (std::size_t p = 0; p < e.parameters.size(); ++p) {
      o += fmt::format(
          "  {:<8} {:>14} {:>12}\n", e.parameters[p].name, Value(e.theta[p]),
          std::isfinite(e.sigma[p]) ? fmt::format("{:.2g}", e.sigma[p]) : "undetermined");
    }
    const SensorKind sensor = SensorOf(in, r.model);
    for (std::size_t k = 0; k < fe.after.size(); ++k) {
      const auto& a = fe.after[k];
      const auto [unit, f] = MisfitUnit(a.kind, sensor, fe.relative_scale);
      const MisfitFigure* b = k < fe.before.size() ? &fe.before[k] : nullptr;
      o += fmt::format(
          "  {} misfit over {}: before RMS {} max {}, after RMS {:.4g} max {:.4g} {}\n", a.kind,
          a.count, b ? fmt::format("{:.4g}", b->rms * f) : "-",
          b ? fmt::format("{:.4g}", b->max_abs * f) : "-", a.rms * f, a.max_abs * f, unit);
    }
    if (const auto b = LargestNormBias(fe); b.second >= 0.1) {
      o += fmt::format(
          "  second-order bias from the values' noise removed: {:.2f} sigma on {} (the largest; "
          "the coverage is weak)\n",
          b.second, b.first);
    }
    o +=
        fmt::format("  coverage: {} of {} bins ({:.1f} %) from {} directions\n", fe.coverage.filled,
                    fe.coverage.total, 100 * fe.coverage.fraction(), fe.coverage.directions);
    if (fe.gap.radius_deg >= kGapWorthSayingDeg) {
      o += "  uncovered: " + CoverageGapText(fe.gap, sensor, in.context.dip_deg) + "\n";
    }
    if (!fe.analysis.weak.empty()) {
      const auto& w = fe.analysis.weak.back();
      o += fmt::format("  weakest direction ({:.2g} of the strongest): {}\n",
                       w.relative_singular_value, w.text);
    }
    if (!fe.undetermined.empty()) {
      std::string names;
      for (const auto& n : fe.undetermined) names += (names.empty() ? "" : ", ") + n;
      o += fmt::format("  not determined by these data: {}\n", names);
    }
    if (fe.gate_passed) {
      o += "  gate: passed\n";
    } else {
      o += "  gate: refused\n";
      for (const auto& why : fe.gate_reasons) o += fmt::format("    - {}\n", why);
    }
    if (i < in.advice.size() && in.advice[i])
      o += "  next orientation: " + AdviceText(*in.advice[i]) + "\n";
    if (r.model == "gyro9" && e.fit.verdict == FitVerdict::kTooLarge) {
      o += "  hint: a gyro whose bias moves with its orientation fits gyro9g (the g-sensitivity): "
           "--models accel9,gyro9g\n";
    }
  }
  return o;
}

nlohmann::json FreeReportJson(const FreeReportInput& in) {
  nlohmann::json intervals = nlohmann::json::array();
  for (const auto& iv : in.found.intervals) {
    nlohmann::json j = {{"t_start_s", iv.t_start_s}, {"t_end_s", iv.t_end_s}};
    if (iv.acc) j["acc_mean"] = {iv.acc->mean.x(), iv.acc->mean.y(), iv.acc->mean.z()};
    if (iv.gyr) j["gyr_mean"] = {iv.gyr->mean.x(), iv.gyr->mean.y(), iv.gyr->mean.z()};
    if (iv.mag) j["mag_mean"] = {iv.mag->mean.x(), iv.mag->mean.y(), iv.mag->mean.z()};
    if (iv.move_in) j["move_s"] = iv.move_in->duration_s();
    intervals.push_back(j);
  }
  nlohmann::json models = nlohmann::json::array();
  for (std::size_t i = 0; i < in.results.size(); ++i) {
    const FreeModelResult& r = in.results[i];
    const Estimate& e = r.estimate.estimate;
    // The station's result (protocol/free_json.h), with the parameters also as a list in the
    // model's order with their units, the covariance, and the gate's verdict as "passed".
    nlohmann::json m = protocol::FreeResultJson(
        r, i < in.advice.size() ? in.advice[i] : std::optional<OrientationAdvice>());
    m["gate"]["passed"] = m["gate"]["pass"];
    if (!e.ok) {
      models.push_back(m);
      continue;
    }
    nlohmann::json params = nlohmann::json::array();
    for (std::size_t p = 0; p < e.parameters.size(); ++p) {
      params.push_back({{"name", e.parameters[p].name},
                        {"unit", ToString(e.parameters[p].unit)},
                        {"value", e.theta[p]},
                        {"sigma", std::isfinite(e.sigma[p]) ? nlohmann::json(e.sigma[p])
                                                            : nlohmann::json(nullptr)}});
    }
    nlohmann::json cov = nlohmann::json::array();
    for (int a = 0; a < e.covariance.rows(); ++a) {
      nlohmann::json row = nlohmann::json::array();
      for (int b = 0; b < e.covariance.cols(); ++b) row.push_back(e.covariance(a, b));
      cov.push_back(row);
    }
    m["parameters"] = params;
    m["covariance"] = cov;
    m["fit"] = m["fit_check"];
    models.push_back(m);
  }
  nlohmann::json out = {{"source", in.source},         {"summary", in.found.summary},
                        {"skipped", in.found.skipped}, {"skip_reasons", in.found.skip_reasons},
                        {"intervals", intervals},      {"models", models}};
  if (in.motion) {
    const MotionPoints& m = *in.motion;
    out["motion"] = {{"points", m.points.size()},
                     {"samples_with_mag", m.samples_with_mag},
                     {"held", m.held},
                     {"in_intervals", m.in_intervals},
                     {"in_noise_measurement", m.in_noise_measurement},
                     {"decimated", m.decimated},
                     {"rate_hz", m.period_s > 0 ? 1.0 / m.period_s : 0.0},
                     {"sigma", {m.sigma.x(), m.sigma.y(), m.sigma.z()}},
                     {"noise_source", m.noise_source},
                     {"summary", m.Summary()}};
    if (m.bandwidth_hz > 0) {
      out["motion"]["bandwidth_hz"] = m.bandwidth_hz;
      out["motion"]["fastest_turn_dps"] = m.fastest_turn_radps * 180 / M_PI;
      out["motion"]["smallest_attenuation"] = m.smallest_attenuation;
    }
  }
  return out;
}

std::string CoverageSphereSvg(const FreeEstimate& fe, const std::string& id) {
  const double cell = 12, W = kCoverageLongitudeBins * cell, H = kCoverageLatitudeBins * cell;
  const double R = H / 2, gap = 30, total_w = W + 2 * (2 * R + gap) + 20;
  std::string o =
      svg::Open(id, total_w, H + 40, "Coverage sphere",
                fmt::format("{} of {} latitude-longitude bins hold a direction ({:.1f} %)",
                            fe.coverage.filled, fe.coverage.total, 100 * fe.coverage.fraction()));
  o += fmt::format(
      "<text x=\"0\" y=\"14\">bins: latitude (rows, -90 at the bottom) by longitude "
      "(columns, -180 at the left); {} of {} filled</text>\n",
      fe.coverage.filled, fe.coverage.total);
  for (int la = 0; la < kCoverageLatitudeBins; ++la) {
    for (int lo = 0; lo < kCoverageLongitudeBins; ++lo) {
      const int n =
          fe.coverage.counts.empty()
              ? 0
              : fe.coverage.counts[static_cast<std::size_t>(la * kCoverageLongitudeBins + lo)];
      o += fmt::format(
          "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"{}\" stroke=\"#ddd\"/>\n",
          svg::Num(lo * cell), svg::Num(20 + (kCoverageLatitudeBins - 1 - la) * cell),
          svg::Num(cell), svg::Num(cell), n > 0 ? "#2c6fbb" : "white");
    }
  }
  // The directions seen from above (+z towards the viewer) and from below.
  for (int side = 0; side < 2; ++side) {
    const double cx = W + 20 + R + side * (2 * R + gap), cy = 20 + R;
    o += fmt::format("<circle cx=\"{}\" cy=\"{}\" r=\"{}\" fill=\"#f4f4f4\" stroke=\"#888\"/>\n",
                     svg::Num(cx), svg::Num(cy), svg::Num(R));
    o += fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\n", svg::Num(cx),
                     svg::Num(cy + R + 14), side == 0 ? "seen from +z" : "seen from -z");
    for (const auto& d : fe.directions) {
      const Eigen::Vector3d u = d.normalized();
      if ((side == 0) != (u.z() >= 0)) continue;
      const double x = cx + R * u.x() * (side == 0 ? 1 : -1), y = cy - R * u.y();
      o += fmt::format("<circle cx=\"{}\" cy=\"{}\" r=\"3\" fill=\"#c0392b\"/>\n", svg::Num(x),
                       svg::Num(y));
    }
  }
  o += svg::Close();
  return o;
}

std::string FreeReportHtml(const FreeReportInput& in) {
  std::string o = fmt::format(
      "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>turncal: {}"
      "</title><style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto}}"
      "table{{border-collapse:collapse}}td,th{{padding:2px 8px;border-bottom:1px solid #ddd;"
      "text-align:right}}th:first-child,td:first-child{{text-align:left}}.refused{{color:#b00}}"
      ".passed{{color:#070}}pre{{background:#f6f6f6;padding:8px}}</style></head><body>\n",
      svg::Escape(in.title));
  o += "<h1>" + svg::Escape(in.title) + "</h1>\n";
  o += FreeReportBody(in);
  o += "</body></html>\n";
  return o;
}

std::string FreeReportBody(const FreeReportInput& in) {
  std::string o;
  o += fmt::format("<p>{}<br>{}{}</p>\n", svg::Escape(in.source), svg::Escape(in.found.summary),
                   in.motion ? "<br>" + svg::Escape(in.motion->Summary()) : std::string());
  if (!in.lines.empty()) {
    o += "<ul class=\"small\">";
    for (const auto& line : in.lines) o += "<li>" + svg::Escape(line) + "</li>";
    o += "</ul>\n";
  }
  for (std::size_t i = 0; i < in.results.size(); ++i) {
    const FreeModelResult& r = in.results[i];
    const FreeEstimate& fe = r.estimate;
    const Estimate& e = fe.estimate;
    o += fmt::format("<h2 id=\"{0}\">{0}</h2>\n", svg::Escape(r.model));
    if (!r.note.empty()) o += fmt::format("<p>{}</p>\n", svg::Escape(r.note));
    if (!e.ok) {
      o += fmt::format("<p class=\"refused\">not fitted: {}</p>\n", svg::Escape(e.error));
      continue;
    }
    o += fmt::format("<p class=\"{}\">gate: {}</p>\n", fe.gate_passed ? "passed" : "refused",
                     fe.gate_passed ? "passed" : "refused");
    if (!fe.gate_reasons.empty()) {
      o += "<ul>";
      for (const auto& why : fe.gate_reasons) o += "<li>" + svg::Escape(why) + "</li>";
      o += "</ul>\n";
    }
    o += fmt::format(
        "<p>{} intervals{}, {} residuals; rank {} of {}; chi<sup>2</sup>/dof {:.2f} (p "
        "{:.2g}){}</p>\n",
        fe.intervals,
        fe.motion_points > 0 ? fmt::format(" ({} of them samples in motion)", fe.motion_points)
                             : "",
        fe.residuals, e.rank, e.parameters.size(), e.dof > 0 ? e.chi2 / e.dof : 0.0, e.p_value,
        e.covariance_scale > 1 ? fmt::format("; covariance inflated x{:.2f}", e.covariance_scale)
                               : "");
    o += "<table><tr><th>parameter</th><th>value</th><th>1 sigma</th></tr>\n";
    for (std::size_t p = 0; p < e.parameters.size(); ++p) {
      o += fmt::format(
          "<tr><td>{}</td><td>{}</td><td>{}</td></tr>\n", svg::Escape(e.parameters[p].name),
          Value(e.theta[p]),
          std::isfinite(e.sigma[p]) ? fmt::format("{:.2g}", e.sigma[p]) : "undetermined");
    }
    o += "</table>\n";
    const SensorKind sensor = SensorOf(in, r.model);
    o += "<table><tr><th>misfit</th><th>intervals</th><th>before RMS</th><th>before max</th>"
         "<th>after RMS</th><th>after max</th><th>unit</th></tr>\n";
    for (std::size_t k = 0; k < fe.after.size(); ++k) {
      const auto& a = fe.after[k];
      const auto [unit, f] = MisfitUnit(a.kind, sensor, fe.relative_scale);
      const MisfitFigure* b = k < fe.before.size() ? &fe.before[k] : nullptr;
      o += fmt::format(
          "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{:.4g}</td><td>{:.4g}</td>"
          "<td>{}</td></tr>\n",
          svg::Escape(a.kind), a.count, b ? fmt::format("{:.4g}", b->rms * f) : "-",
          b ? fmt::format("{:.4g}", b->max_abs * f) : "-", a.rms * f, a.max_abs * f,
          svg::Escape(unit));
    }
    o += "</table>\n";
    if (!fe.analysis.weak.empty()) {
      o += fmt::format("<p>Weakest direction ({:.2g} of the strongest): {}</p>\n",
                       fe.analysis.weak.back().relative_singular_value,
                       svg::Escape(fe.analysis.weak.back().text));
    }
    if (i < in.advice.size() && in.advice[i]) {
      o += "<p>Next orientation: " + svg::Escape(AdviceText(*in.advice[i])) + "</p>\n";
    }
    o += CoverageSphereSvg(fe, "coverage-" + r.model);
    if (fe.gap.radius_deg >= kGapWorthSayingDeg) {
      o += "<p>Uncovered: " +
           svg::Escape(CoverageGapText(fe.gap, SensorOf(in, r.model), in.context.dip_deg)) +
           "</p>\n";
    }
    if (const auto values = BeforeAfterValues(in, r)) {
      o += BeforeAfterSvg(*values, "sphere-" + r.model);
    }
  }
  return o;
}

bool FreeCalibrationsReport(const std::vector<nlohmann::json>& calibrations,
                            const std::string& source, FreeReportInput* out, std::string* error) {
  *out = FreeReportInput{};
  std::vector<protocol::FreeCalibrationDocument> docs(calibrations.size());
  std::size_t most = 0;
  for (std::size_t i = 0; i < calibrations.size(); ++i) {
    if (!protocol::ParseFreeCalibration(calibrations[i], &docs[i], error)) return false;
    if (docs[i].intervals.empty()) {
      *error = fmt::format("{} {}: the calibration holds no intervals to re-fit", docs[i].device,
                           docs[i].requested);
      return false;
    }
    if (docs[i].intervals.size() > docs[most].intervals.size()) most = i;
  }
  if (docs.empty()) {
    *error = "no calibration to report";
    return false;
  }
  out->title = docs[0].device + ": calibration without a turntable";
  out->source = fmt::format("{}, the active calibrations of {}", source, docs[0].device);
  out->context = docs[most].context;
  out->found.intervals = docs[most].intervals;
  out->found.summary = fmt::format("free mode: {} static intervals", docs[most].intervals.size());
  for (const auto& doc : docs) {
    std::vector<FreeModelResult> results;
    if (!CalibrateFreeModels({doc.requested}, doc.intervals, doc.context, doc.options, &results,
                             error)) {
      return false;
    }
    const auto advice = NextOrientations(results, doc.intervals, doc.context);
    for (std::size_t k = 0; k < results.size(); ++k) {
      // An upstream fitted for this model is shown once (the requested model's own document wins).
      const bool requested = results[k].requested == doc.requested;
      bool shown = false;
      for (const auto& r : out->results) shown = shown || r.model == results[k].model;
      if (!requested && shown) continue;
      if (!requested) {
        bool has_own = false;
        for (const auto& d : docs) has_own = has_own || d.requested == results[k].model;
        if (has_own) continue;
      }
      if (requested) {
        const Estimate& e = results[k].estimate.estimate;
        double worst = 0.0;
        const bool same_model =
            results[k].model == doc.model && e.ok && e.theta.size() == doc.theta.size();
        for (Eigen::Index p = 0; same_model && p < e.theta.size(); ++p) {
          const double s = e.sigma[p] > 0 && std::isfinite(e.sigma[p]) ? e.sigma[p] : 1.0;
          worst = std::max(worst, std::abs(e.theta[p] - doc.theta[p]) / s);
        }
        out->lines.push_back(fmt::format(
            "{}: version {}{}, turncal {}, {}; {} intervals; {}", doc.requested, doc.version,
            doc.model != doc.requested ? " (fitted as " + doc.model + ")" : "", doc.software,
            doc.time, doc.intervals.size(),
            !same_model ? std::string("the re-fit no longer gives this model's estimate")
            : worst < 1e-6
                ? std::string("re-fitted from them: the stored values agree")
                : fmt::format("re-fitted from them: the stored values differ by up to {:.2g} "
                              "sigma (shown: the re-fit)",
                              worst)));
        if (!doc.override_who.is_null()) {
          out->lines.push_back(fmt::format("{}: published by operator override: {}", doc.requested,
                                           doc.override_who.dump()));
        }
      }
      out->results.push_back(results[k]);
      out->advice.push_back(k < advice.size() ? advice[k] : std::nullopt);
    }
  }
  return true;
}

}  // namespace turncal::report
