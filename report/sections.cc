#include "report/sections.h"

#include <fmt/format.h>

#include <cmath>

#include "core/modeling/accel_physical.h"
#include "report/plots.h"
#include "report/svg.h"

namespace turncal::report {
namespace {

using svg::Escape;

std::string List(const std::vector<std::string>& items, const char* css_class) {
  if (items.empty()) return "";
  std::string o = fmt::format(R"(<ul class="{}">)", css_class);
  for (const auto& s : items) o += "<li>" + Escape(s) + "</li>";
  return o + "</ul>";
}

// "1.234e-05" style full precision for data attributes; "" for non-finite values.
std::string Exact(double v) { return std::isfinite(v) ? fmt::format("{:.17g}", v) : ""; }

std::string Shown(const ParameterInfo& p, double v, bool is_sigma) {
  if (!std::isfinite(v)) return is_sigma ? "undetermined" : "&#8212;";
  const DisplayQuantity q = ForDisplay(p, v, is_sigma);
  return Escape(is_sigma ? fmt::format("{:.3g}", q.value) : fmt::format("{:.6g}", q.value));
}

// A 3 x 3 matrix as a small table, with 1 sigma per entry when known.
std::string MatrixHtml(const std::string& caption, const Mat3<double>& m,
                       const Mat3<double>* sigma) {
  std::string o = "<table class=\"matrix\"><caption>" + Escape(caption) + "</caption>";
  for (int r = 0; r < 3; ++r) {
    o += "<tr>";
    for (int c = 0; c < 3; ++c) {
      o += fmt::format("<td>{:+.7f}", m(r, c));
      if (sigma && std::isfinite((*sigma)(r, c))) {
        o += fmt::format(" <span class=\"sigma\">&#177; {:.2g}</span>", (*sigma)(r, c));
      }
      o += "</td>";
    }
    o += "</tr>";
  }
  return o + "</table>";
}

Mat3<double> AccelG(const Eigen::VectorXd& theta, const Mat3<double>& mounting) {
  AccelPhysical p;
  p.S = theta.segment<3>(0);
  p.alpha = theta.segment<3>(3);
  p.eps = theta.segment<3>(6);
  return AccelGFromPhysical(p, mounting);
}

// 1 sigma of each entry of G(theta): J cov J^T by central differences (steps of 1e-7).
bool AccelGSigma(const protocol::CalibrationDocument& doc, Mat3<double>* sigma) {
  const Eigen::Index n = doc.theta.size();
  if (doc.covariance.rows() != n || !doc.covariance.allFinite()) return false;
  Eigen::MatrixXd jacobian(9, n);
  Eigen::VectorXd t = doc.theta;
  for (Eigen::Index k = 0; k < n; ++k) {
    const double h = 1e-7;
    t[k] = doc.theta[k] + h;
    const Mat3<double> up = AccelG(t, doc.context.mounting);
    t[k] = doc.theta[k] - h;
    const Mat3<double> down = AccelG(t, doc.context.mounting);
    t[k] = doc.theta[k];
    const Mat3<double> d = (up - down) / (2 * h);
    for (int e = 0; e < 9; ++e) jacobian(e, k) = d(e / 3, e % 3);
  }
  const Eigen::VectorXd var = (jacobian * doc.covariance * jacobian.transpose()).diagonal();
  for (int e = 0; e < 9; ++e) (*sigma)(e / 3, e % 3) = std::sqrt(std::max(var[e], 0.0));
  return true;
}

}  // namespace

std::string GateHtml(const protocol::CalibrationDocument& doc) {
  const GateResult& g = doc.gate;
  std::string o = fmt::format(R"(<p class="verdict {}">Publish gate: <strong>{}</strong>)",
                              g.pass ? "pass" : "fail", g.pass ? "PASS" : "FAIL");
  if (!doc.override_who.is_null()) {
    o += " &#8212; published by operator override: " + Escape(doc.override_who.dump());
  }
  o += "</p>";
  if (!g.reasons.empty()) o += "<h4>Reasons</h4>" + List(g.reasons, "reasons");
  if (!g.missing.empty()) {
    o += "<h4>Not determined by the poses</h4>" + List(g.missing, "missing");
  }
  if (!g.notes.empty()) o += "<h4>Notes</h4>" + List(g.notes, "notes");
  return o;
}

std::string ParameterTableHtml(const protocol::CalibrationDocument& doc) {
  const MeasurementModel& model = *doc.measurement_model;
  std::string o = fmt::format(
      R"(<table class="params" id="params-{}"><thead><tr><th>parameter</th><th>kind</th>)"
      R"(<th>value</th><th>1&#963;</th><th>gate tolerance</th><th>&#963; / tolerance</th>)"
      R"(<th>unit</th><th>value (SI)</th></tr></thead><tbody>)",
      Escape(doc.model));
  const auto& params = model.parameters();
  for (std::size_t i = 0; i < params.size(); ++i) {
    const ParameterInfo& p = params[i];
    const auto k = static_cast<Eigen::Index>(i);
    const double value = doc.theta[k], sigma = doc.sigma[k];
    const auto tol = doc.tolerances.find(p.name);
    std::string tolerance = "&#8212;", ratio = "not gated", state = "ungated";
    if (tol != doc.tolerances.end()) {
      tolerance = Shown(p, tol->second, true);
      if (std::isfinite(sigma)) {
        ratio = fmt::format("{:.3g}", sigma / tol->second);
        state = sigma <= tol->second ? "within" : "exceeds";
      } else {
        ratio = "&#8734;";
        state = "exceeds";
      }
    }
    std::string unit = ForDisplay(p, value, false).unit;
    if (unit.empty()) unit = "1";
    o += fmt::format(
        R"(<tr id="param-{}-{}" class="{}" data-value="{}" data-sigma="{}"><td>{}</td><td>{}</td>)"
        R"(<td class="num">{}</td><td class="num">{}</td><td class="num">{}</td>)"
        R"(<td class="num">{}</td><td>{}</td><td class="num">{}</td></tr>)",
        Escape(doc.model), Escape(p.name), state, Exact(value), Exact(sigma), Escape(p.name),
        ToString(p.kind), Shown(p, value, false), Shown(p, sigma, true), tolerance, ratio,
        Escape(unit), Escape(fmt::format("{:.9g}", value)));
  }
  o += "</tbody></table>";
  o += R"(<p class="small">Units: scale factors in ppm, angles in degrees (alpha3 as its )"
       R"(deviation from 90&#176;), accelerometer biases in mg (1 g = 9.80665 m/s&#178;), )"
       R"(magnetometer biases and fields in mG when the device reports Gauss (otherwise 1000 )"
       R"(&#215; the device's unit); gains (G, K) are dimensionless.)";
  if (!doc.tolerances_recorded) {
    o += " The calibration does not record its gate tolerances: those shown are the industrial "
         "class's defaults.";
  }
  return o + "</p>";
}

std::string PhysicalFormHtml(const protocol::CalibrationDocument& doc) {
  const MeasurementModel& model = *doc.measurement_model;
  std::string o;
  if (model.sensor() == SensorKind::kAccelerometer) {
    Mat3<double> sigma;
    const bool with_sigma = AccelGSigma(doc, &sigma);
    o += "<p>The parameters above are the physical form (S, &#945;, &#949;). The same sensor "
         "matrix as the linear form's G = (I+S) T<sub>r</sub><sup>s</sup> C<sub>q</sub><sup>r</sup>"
         ", with 1&#963; propagated from the covariance:</p>";
    o += MatrixHtml("G (accelerometer)", AccelG(doc.theta, doc.context.mounting),
                    with_sigma ? &sigma : nullptr);
    return o;
  }
  if (model.sensor() == SensorKind::kGyroscope) {
    Mat3<double> sigma;
    const bool with_sigma = AccelGSigma(doc, &sigma);
    o += "<p>The gyroscope's G<sub>&#969;</sub> = (I+S) T<sub>r</sub><sup>s</sup> "
         "C<sub>q</sub><sup>r</sup> maps the inertial rate in the table frame to the reading "
         "(scale factors in ppm, misalignment in degrees above; bias in deg/h), with 1&#963; "
         "propagated from the covariance:</p>";
    o += MatrixHtml("G (gyroscope)", AccelG(doc.theta, doc.context.mounting),
                    with_sigma ? &sigma : nullptr);
    if (const int b = model.index_of("Bg_xx"); b >= 0) {
      Mat3<double> B, Bs;
      constexpr double kDegHourPerG = 180 / M_PI * 3600 * 9.80665;
      for (int e = 0; e < 9; ++e) {
        B(e / 3, e % 3) = doc.theta[b + e] * kDegHourPerG;
        Bs(e / 3, e % 3) = doc.sigma.size() > b + e ? doc.sigma[b + e] * kDegHourPerG : NAN;
      }
      o += MatrixHtml(
          "B_g, deg/h/g (output axis i's response to the specific force along q's "
          "axis j)",
          B, &Bs);
    }
    return o;
  }
  const int g11 = model.index_of("g11");
  if (g11 < 0) {
    // mag-physical: its 22 parameters are the physical breakdown, of which a turntable sees only
    // 13 combinations (MODELS.md); no single G is shown for it.
    o += "<p>This model is written in physical parameters (S, &#945;, &#949;, K, &#948;B); a "
         "turntable test determines only 13 combinations of them (see the observability summary). "
         "Use mag13 for a correction.</p>";
    return o;
  }
  Mat3<double> G;
  for (int e = 0; e < 9; ++e) G(e / 3, e % 3) = doc.theta[g11 + e];
  o += "<p>G absorbs the sensor's scale factors, axis non-orthogonality, mounting and the soft "
       "iron around it, in the device's unit: a magnetometer model on a turntable has no unique "
       "physical decomposition (MODELS.md). ";
  o += model.corrected_frame() == OutputFrame::kTable
           ? "Corrected output is the field in the table frame q: <span class=\"formula\">"
             "B<sub>q</sub> = G<sup>&#8722;1</sup>(B<sub>m</sub> &#8722; b)</span>.</p>"
           : "</p>";
  Mat3<double> sigma;
  bool with_sigma = doc.sigma.size() >= g11 + 9;
  for (int e = 0; with_sigma && e < 9; ++e) sigma(e / 3, e % 3) = doc.sigma[g11 + e];
  o += MatrixHtml("G (magnetometer)", G, with_sigma ? &sigma : nullptr);
  const int k11 = model.index_of("k11");
  if (k11 >= 0) {
    const double* k = doc.theta.data() + k11;
    Mat3<double> K;
    K << k[0], k[1], k[2], k[1], k[3], k[4], k[2], k[4], k[5];
    o += MatrixHtml("K_ = K^-1 (k11 ... k33: the platform's soft iron, symmetric)", K, nullptr);
  }
  if (!doc.gauge.empty()) {
    o += "<p class=\"gauge\">Gauge: " + Escape(doc.gauge) +
         ". G, K and dB are given in this gauge; two directions of the parameters are not "
         "observable on a turntable, and G (hence the live correction) depends on the "
         "gauge (MODELS.md, \"The mag22 gauge\").</p>";
  }
  return o;
}

std::string ResidualSummaryHtml(const protocol::CalibrationDocument& doc, const ModelAnalysis& a) {
  if (!a.has_records) {
    return "<p class=\"missing\">No residuals: " + Escape(a.no_records_reason) + ".</p>";
  }
  const ResidualUnit unit = ResidualUnitFor(*doc.measurement_model);
  const PoseResiduals& r = a.residuals;
  std::string o = fmt::format(
      R"(<table class="residual-rms" id="rms-{}"><thead><tr><th>axis</th><th>RMS before ({})</th>)"
      R"(<th>RMS after ({})</th><th>before / after</th></tr></thead><tbody>)",
      Escape(doc.model), unit.name, unit.name);
  auto row = [&](const std::string& axis, double before, double after) {
    o += fmt::format(
        R"(<tr data-axis="{}"><td>{}</td><td class="num rms-before" data-value="{}">{:.4g}</td>)"
        R"(<td class="num rms-after" data-value="{}">{:.4g}</td><td class="num">{:.3g}</td></tr>)",
        axis, axis, Exact(before), before * unit.per_triad_unit, Exact(after),
        after * unit.per_triad_unit, after > 0 ? before / after : INFINITY);
  };
  for (int i = 0; i < 3; ++i) row(std::string(1, "xyz"[i]), r.rms_before[i], r.rms_after[i]);
  row("all", r.rms_before_total, r.rms_after_total);
  o += "</tbody></table>";
  o += fmt::format(
      "<p class=\"small\">{} poses with {} data. data-value attributes hold the RMS in the "
      "triad's own unit ({}).</p>",
      r.after.size(), ToString(doc.measurement_model->sensor()),
      doc.measurement_model->sensor() == SensorKind::kAccelerometer ? "m/s&#178;"
      : doc.measurement_model->sensor() == SensorKind::kGyroscope   ? "rad/s"
                                                                    : "the device's unit");
  return o;
}

std::string SourcesHtml(const protocol::CalibrationDocument& doc, const ModelAnalysis& a) {
  const SourceSigmas& src = a.sources;
  const MeasurementModel& model = *doc.measurement_model;
  std::string o = fmt::format(
      R"(<table class="sources" id="sources-{}"><thead><tr><th>parameter</th>)", Escape(doc.model));
  for (std::size_t k = 0; k < src.source.size(); ++k) {
    o += fmt::format("<th>1&#963; from {} alone ({})</th>", Escape(src.source[k]), src.records[k]);
  }
  o += "<th>1&#963; from all</th><th>determined by</th></tr></thead><tbody>";
  for (int j = 0; j < model.num_parameters(); ++j) {
    const ParameterInfo& p = model.parameters()[static_cast<std::size_t>(j)];
    o += fmt::format(R"(<tr id="source-{}-{}"><td>{}</td>)", Escape(doc.model), Escape(p.name),
                     Escape(p.name));
    std::vector<std::string> by;
    for (std::size_t k = 0; k < src.source.size(); ++k) {
      const double s = src.sigma[k][j];
      o += fmt::format(R"(<td class="num" data-sigma="{}">{}</td>)", Exact(s),
                       Escape(FormatSigma(p, s)));
      // A source determines a parameter alone when its sigma is within 3x of the combined one.
      if (std::isfinite(s) && s <= 3 * src.sigma_all[j]) by.push_back(src.source[k]);
    }
    std::string verdict = by.empty() ? "together" : by.front();
    if (by.size() > 1) {
      verdict = "either (" + by[0];
      for (std::size_t k = 1; k < by.size(); ++k) {
        verdict += (k + 1 == by.size() ? " or " : ", ") + by[k];
      }
      verdict += ")";
    }
    o += fmt::format(R"(<td class="num">{}</td><td>{}</td></tr>)",
                     Escape(FormatSigma(p, src.sigma_all[j])), Escape(verdict));
  }
  o += "</tbody></table>";
  o += "<p class=\"small\">Each source's records alone, weighed as the observability analysis "
       "weighs them, by the Fisher information at the estimate; inf: that source alone cannot "
       "determine the parameter. \"Determined by\" names a source whose sigma alone is within 3"
       "&#215; of the combined one; \"together\" means none comes near alone.</p>";
  return o;
}

std::string RateLinearityHtml(const protocol::CalibrationDocument& doc, const ModelAnalysis& a) {
  const RateLinearity& r = a.linearity;
  std::string o = fmt::format(
      R"(<table class="linearity" id="linearity-{}"><thead><tr><th>|rate| (&#176;/s)</th>)"
      "<th>segments</th><th>scale error (ppm)</th><th>1&#963; (ppm)</th></tr></thead><tbody>",
      Escape(doc.model));
  for (const RateLevel& l : r.levels) {
    o += fmt::format(
        R"(<tr><td class="num">{:g}</td><td class="num">{}</td><td class="num">{:+.1f}</td>)"
        R"(<td class="num">{:.1f}</td></tr>)",
        l.rate_dps, l.segments, l.scale_error * 1e6, l.sigma * 1e6);
  }
  o += "</tbody></table>";
  o += fmt::format(R"(<p id="linearity-finding-{}">{}.)", Escape(doc.model), Escape(r.finding));
  if (r.has_asymmetry) {
    o += fmt::format(" Positive rates read {:+.1f} &#177; {:.1f} ppm more than negative ones.",
                     r.asymmetry * 1e6, r.asymmetry_sigma * 1e6);
  }
  o += R"(</p><p class="small">Each rate segment's residual along the table's rate, relative to )"
       "it, at the estimate: a linear gyro's scatter about zero at every rate (the scale factors "
       "absorb their mean per axis). The sigmas are the records'.</p>";
  return o;
}

std::string ObservabilityHtml(const protocol::CalibrationDocument& doc, const ModelAnalysis& a) {
  std::string o = fmt::format(
      "<p>Rank recorded with the calibration: {} of {} parameters ({} when the model's gauge "
      "directions are set aside).</p>",
      doc.rank, doc.measurement_model->num_parameters(),
      doc.measurement_model->num_parameters() - doc.measurement_model->gauge_dimension());
  if (!a.observability_done) {
    return o +
           "<p class=\"missing\">No data-level analysis: the calibration carries no pose "
           "measurements.</p>";
  }
  const DataReport& d = a.observability;
  const RankAnalysis& r = d.analysis;
  o += fmt::format(R"(<table class="observability" id="observability-{}"><tbody>)"
                   R"(<tr><th>numerical rank</th><td class="rank">{} of {} (expected {})</td></tr>)"
                   R"(<tr><th>condition number</th><td class="condition">{:.4g}</td></tr>)",
                   Escape(doc.model), r.rank, r.columns, d.expected_rank, r.condition);
  if (r.rank > 0 && r.rank < r.columns && r.relative_singular.size() >= r.rank) {
    // The null directions (mag22's gauge) make the condition number infinite in principle.
    o += fmt::format(
        R"(<tr><th>condition number of the determined directions</th><td>{:.4g}</td></tr>)",
        1.0 / r.relative_singular[r.rank - 1]);
  }
  const NamedDirection* weakest = nullptr;
  for (const auto& w : r.weak) {
    if (!weakest || w.relative_singular_value < weakest->relative_singular_value) weakest = &w;
  }
  if (weakest) {
    o += fmt::format(R"(<tr><th>weakest direction</th><td class="weakest">{} <span class="small">)"
                     R"((relative singular value {:.3g})</span></td></tr>)",
                     Escape(weakest->text), weakest->relative_singular_value);
  }
  for (const auto& n : r.null) {
    o += fmt::format(R"(<tr><th>null direction</th><td class="null">{}</td></tr>)", Escape(n.text));
  }
  if (!d.gauge.empty()) {
    o += "<tr><th>gauge</th><td>" + Escape(d.gauge) + "</td></tr>";
  }
  o += fmt::format(
      "<tr><th>pose diversity</th><td>{} poses, {} distinct down directions, "
      "regressor rank {} of 10</td></tr>",
      d.diversity.poses, d.diversity.distinct_down, d.diversity.regressor_rank);
  o += "</tbody></table>";
  o += List(d.diversity.findings, "findings");
  o += "<p class=\"small\">Computed at the estimate over the calibration's poses, with the "
       "calibrator's weights; columns scaled by each parameter's nominal size "
       "(core/analysis/observability.h).</p>";
  return o;
}

}  // namespace turncal::report
