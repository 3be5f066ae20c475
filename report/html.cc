#include "report/html.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "protocol/calibration_json.h"
#include "protocol/free_json.h"
#include "protocol/thermal_json.h"
#include "report/analysis.h"
#include "report/device_writes.h"
#include "report/drift_section.h"
#include "report/free_report.h"
#include "report/plots.h"
#include "report/sections.h"
#include "report/svg.h"
#include "report/thermal_report.h"
#include "turncal/version.h"

namespace turncal::report {
namespace {

using svg::Escape;

constexpr const char* kStyle = R"(
body { font: 14px/1.45 system-ui, sans-serif; color: #222; margin: 24px auto; max-width: 960px; padding: 0 12px; }
h1 { font-size: 22px; margin-bottom: 4px; } h2 { font-size: 18px; border-bottom: 2px solid #ccc; margin-top: 36px; }
h3 { font-size: 15px; margin: 20px 0 6px; } h4 { font-size: 13px; margin: 8px 0 2px; }
table { border-collapse: collapse; margin: 6px 0; } th, td { padding: 2px 8px; border-bottom: 1px solid #e4e4e4; text-align: left; }
.observability th, .identity th { white-space: nowrap; } .formula { white-space: nowrap; }
td.num { text-align: right; font-variant-numeric: tabular-nums; } .small { font-size: 12px; color: #555; }
tr.exceeds td { background: #fde8e8; } tr.within td:nth-child(6) { color: #176317; }
.verdict { font-size: 16px; } .verdict.pass strong { color: #176317; } .verdict.fail strong { color: #b00; }
.batch td.pass { color: #176317; } .batch td.fail { color: #b00; }
.missing, .fit-warn { color: #a00; } table.matrix td { font-family: ui-monospace, monospace; border: none; }
table.matrix caption { text-align: left; font-weight: bold; } .sigma { color: #666; }
svg.plot { display: block; margin: 8px 0; background: #fff; }
svg.plot text { font: 11px system-ui, sans-serif; fill: #222; }
svg.plot .plot-title { font-size: 13px; font-weight: bold; } svg.plot .panel-title { font-size: 12px; }
svg.plot .frame { fill: none; stroke: #555; } svg.plot .grid { fill: none; stroke: #e2e2e2; }
svg.plot .zero { stroke: #999; } svg.plot .tolerance { stroke: #c00; stroke-dasharray: 6 3; stroke-width: 1.5; }
svg.plot .sigma-series polyline { fill: none; stroke-width: 1.6; } svg.plot .point-label { font-size: 9px; fill: #555; }
svg.plot .missing { fill: #a00; } svg.plot .residual-after line, svg.plot .residual-before line { stroke-width: 1; }
)";

// Model order of the registry (accel12, accel13, mag-physical, mag13, mag22, ...).
int ModelRank(const std::string& name) {
  const auto names = ModelNames();
  const auto it = std::find(names.begin(), names.end(), name);
  return static_cast<int>(it - names.begin());
}

std::string IdentityHtml(const nlohmann::json& identity) {
  if (!identity.is_object() || identity.empty()) {
    return "<p>Device identity: not recorded (replays and devices without a configuration "
           "dialogue have none).</p>";
  }
  std::string o = "<table class=\"identity\"><caption>Device identity</caption>";
  for (const auto& [key, value] : identity.items()) {
    o += "<tr><th>" + Escape(key) + "</th><td>" +
         Escape(value.is_string() ? value.get<std::string>() : value.dump()) + "</td></tr>";
  }
  return o + "</table>";
}

std::string SummaryHtml(const std::vector<protocol::CalibrationDocument>& docs) {
  std::string o =
      "<table class=\"summary\"><thead><tr><th>model</th><th>version</th><th>calibrated (UTC)"
      "</th><th>software</th><th>poses</th><th>rank</th><th>&#967;&#178; / dof</th><th>gate</th>"
      "</tr></thead><tbody>";
  for (const auto& d : docs) {
    o += fmt::format(
        "<tr><td><a href=\"#model-{0}\">{0}</a></td><td class=\"num\">{1}</td><td>{2}</td>"
        "<td>{3}</td><td class=\"num\">{4}</td><td class=\"num\">{5}</td>"
        "<td class=\"num\">{6:.1f} / {7}</td><td class=\"gate-{8}\">{9}</td></tr>",
        Escape(d.model), d.version, Escape(d.time), Escape(d.software), d.poses.size(), d.rank,
        d.chi2, d.dof, d.gate.pass ? "pass" : "fail", d.gate.pass ? "PASS" : "FAIL");
  }
  return o + "</tbody></table>";
}

std::string ModelSection(const protocol::CalibrationDocument& d) {
  const ModelAnalysis a = AnalyzeCalibration(d);
  const MeasurementModel& model = *d.measurement_model;
  std::string o = fmt::format("<section class=\"model\" id=\"model-{}\">", Escape(d.model));
  o += fmt::format("<h2>{} &#8212; {}, corrected output in the {} frame</h2>", Escape(d.model),
                   ToString(model.sensor()), ToString(model.corrected_frame()));
  const int with_triad = static_cast<int>(a.residuals.after.size());
  o += fmt::format(
      "<p class=\"meta\">Version {} calibrated {} by turncal {}; {} poses ({} with {} "
      "measurements in the calibration); &#967;&#178; {:.2f} for {} degrees of freedom "
      "(p = {:.3g}).",
      d.version, Escape(d.time.empty() ? "(time not recorded)" : d.time),
      Escape(d.software.empty() ? "?" : d.software), d.poses.size(), with_triad,
      ToString(model.sensor()), d.chi2, d.dof, d.p_value);
  if (!d.sensor_class.empty()) o += " Sensor class: " + Escape(d.sensor_class) + ".";
  o += "</p>";
  {
    // The noise model the calibration was made with (docs/ACCURACY.md "Drift").
    const BiasDrift& drift = d.calibrator.drift;
    // mg, deg/h, or mGauss (devices reporting Gauss).
    const ResidualUnit triad_unit = ResidualUnitFor(model);
    const double unit = triad_unit.per_triad_unit;
    const char* unit_name = triad_unit.name;
    std::string text;
    if (drift.enabled()) {
      text = fmt::format(
          "bias drift in time: Gauss&#8211;Markov &#963; {:.3g} {} with &#964; = {:.0f} s",
          drift.gm_sigma.maxCoeff() * unit, unit_name, drift.gm_tau_s);
      if (drift.rw_density.maxCoeff() > 0) {
        text += fmt::format(", random walk {:.3g} {}/&#8730;s", drift.rw_density.maxCoeff() * unit,
                            unit_name);
      }
      if (drift.warmup_sigma.maxCoeff() > 0) {
        text += fmt::format(", warm-up {:.3g} {} settling with &#964; = {:.0f} s",
                            drift.warmup_sigma.maxCoeff() * unit, unit_name, drift.warmup_tau_s);
      }
      if (d.drift_scale) {
        const double used = d.drift_scale_used.value_or(1.0);
        text += fmt::format(
            " ({}; the poses give {:.2f} &#215; the configured drift{})",
            used != 1.0
                ? fmt::format("identified from the poses: {:.2f} &#215; the configured", used)
                : "the configured drift: the poses do not reject it",
            *d.drift_scale,
            d.drift_scale_log_sigma ? fmt::format(", within a factor {:.2f} (1&#963;)",
                                                  std::exp(*d.drift_scale_log_sigma))
                                    : "");
      }
      text +=
          "; the biases hold over the latest pose's window, and corrected output's &#963; grows "
          "with the time since";
    } else {
      text = fmt::format(
          "an independent offset of {:.3g} {} per pose (the model before drift in time: its "
          "&#963; are not honest in an ordered plan)",
          d.calibrator.pose_offset_sigma * unit, unit_name);
    }
    if (model.sensor() == SensorKind::kAccelerometer && d.calibrator.noise_density > 0) {
      text += fmt::format("; white-noise floor {:.3g} &#181;g/&#8730;Hz",
                          d.calibrator.noise_density * 1e6 / 9.80665);
    } else if (model.sensor() == SensorKind::kGyroscope && d.calibrator.noise_density > 0) {
      text += fmt::format("; white-noise floor {:.3g} deg/s/&#8730;Hz",
                          d.calibrator.noise_density * 180 / M_PI);
    }
    o += "<p class=\"meta\"><strong>Noise model:</strong> " + text + ".</p>";
  }
  if (!d.fit_message.empty()) {
    o += fmt::format("<p class=\"fit-{}\"><strong>Fit check:</strong> {}.</p>",
                     d.fit_verdict == "ok" ? "ok" : "warn", Escape(d.fit_message));
  }
  o += "<p class=\"meta\">";
  if (!d.context_recorded) {
    o += " The calibration does not record its reference vectors: the defaults (MODELS.md) are "
         "used.";
  }
  o += "</p>";
  if (!d.gauge.empty()) {
    o += "<p class=\"gauge\"><strong>Gauge:</strong> " + Escape(d.gauge) + "</p>";
  }
  o += "<h3>Gate</h3>" + GateHtml(d);
  o += "<h3>Parameters</h3>" + ParameterTableHtml(d);
  o += "<h3>Sensor matrix</h3>" + PhysicalFormHtml(d);
  if (!a.sources.source.empty()) o += "<h3>What each source determines</h3>" + SourcesHtml(d, a);
  if (a.linearity.segments > 0) o += "<h3>Scale against the rate</h3>" + RateLinearityHtml(d, a);
  o += "<h3>Residuals</h3>" + ResidualSummaryHtml(d, a) + ResidualsSvg(d, a);
  o += "<h3>Pose coverage</h3>" + CoverageSvg(d, a);
  o += "<h3>Convergence</h3>" + ConvergenceSvg(d, a);
  if (a.has_records && !a.convergence.note.empty()) {
    o += "<p class=\"missing\">" + Escape(a.convergence.note) + "</p>";
  } else if (std::isfinite(a.convergence.resolve_max_z)) {
    o += fmt::format(
        "<p class=\"small\">Re-solved with every pose, the calibrator reproduces the stored "
        "estimate to {} &#963;.</p>",
        a.convergence.resolve_max_z < 1e-3 ? std::string("better than 0.001")
                                           : fmt::format("{:.2g}", a.convergence.resolve_max_z));
  }
  o += "<h3>Observability</h3>" + ObservabilityHtml(d, a);
  return o + "</section>\n";
}

// The angle between the gyro and accelerometer triads: both models' C(eps) M are rotations from
// the table frame, so C_gyro C_acc^T turns one triad into the other. Its 1 sigma by central
// differences over both eps (two independent calibrations).
std::string TriadAngleHtml(const std::vector<protocol::CalibrationDocument>& docs) {
  const protocol::CalibrationDocument *acc = nullptr, *gyro = nullptr;
  for (const auto& d : docs) {
    const SensorKind kind = d.measurement_model->sensor();
    if (kind == SensorKind::kAccelerometer && !acc && d.measurement_model->index_of("eps_x") >= 0)
      acc = &d;
    if (kind == SensorKind::kGyroscope && !gyro) gyro = &d;
  }
  if (!acc || !gyro) return "";
  auto eps = [](const protocol::CalibrationDocument& d) -> Eigen::Vector3d {
    return d.theta.segment<3>(d.measurement_model->index_of("eps_x"));
  };
  auto angle = [&](const Eigen::Vector3d& ea, const Eigen::Vector3d& eg) {
    const Mat3<double> R =
        C_eps(eg.x(), eg.y(), eg.z()) * C_eps(ea.x(), ea.y(), ea.z()).transpose();
    return std::acos(std::clamp((R.trace() - 1) / 2, -1.0, 1.0));
  };
  const Eigen::Vector3d ea = eps(*acc), eg = eps(*gyro);
  const double value = angle(ea, eg);
  double var = 0.0;
  bool with_sigma = true;
  for (const auto* d : {acc, gyro}) {
    const int k0 = d->measurement_model->index_of("eps_x");
    if (d->covariance.rows() < k0 + 3 || !d->covariance.block(k0, k0, 3, 3).allFinite()) {
      with_sigma = false;
      break;
    }
    Eigen::RowVector3d J;
    for (int k = 0; k < 3; ++k) {
      const double h = 1e-7;
      Eigen::Vector3d up = d == acc ? ea : eg, down = up;
      up[k] += h;
      down[k] -= h;
      J[k] =
          (d == acc ? angle(up, eg) - angle(down, eg) : angle(ea, up) - angle(ea, down)) / (2 * h);
    }
    var += (J * d->covariance.block(k0, k0, 3, 3) * J.transpose())(0, 0);
  }
  std::string o = "<section class=\"triads\"><h2>Gyroscope and accelerometer triads</h2>";
  o += fmt::format(
      R"(<p id="triad-angle" data-value="{}">The angle between the gyro triad ({}) and the )"
      R"(accelerometer triad ({}): {:.4f}&#176;{}, from their rotations from the table frame )"
      R"((eps of each).</p>)",
      fmt::format("{:.17g}", value), Escape(gyro->model), Escape(acc->model), value * 180 / M_PI,
      with_sigma ? fmt::format(" &#177; {:.4f}&#176;", std::sqrt(var) * 180 / M_PI) : "");
  return o + "</section>\n";
}

// The page up to the header's generation line (the header left open).
std::string PageStart(const std::string& device, const ReportOptions& options) {
  std::string o = "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n";
  o += "<title>Calibration report: " + Escape(device) + "</title>\n";
  o += "<style>" + std::string(kStyle) + "</style>\n</head>\n<body>\n";
  o += "<header><h1>Calibration report: " + Escape(device) + "</h1>";
  o += "<p class=\"small\">turncal " + Escape(kVersion) + " report";
  if (!options.generated_utc.empty()) o += ", generated " + Escape(options.generated_utc);
  if (!options.source.empty()) o += ", from " + Escape(options.source);
  o += ".</p>";
  return o;
}

// The batch summary (ReportOptions::batch): "" for none, or a batch of one unit without a fixture.
std::string BatchHtml(const nlohmann::json& b, const std::string& device) {
  if (!b.is_object() || !b.contains("units") || !b["units"].is_array()) return "";
  const bool fixture = b.value("fixture", nlohmann::json()).is_string();
  if (b["units"].size() < 2 && !fixture) return "";
  auto text = [](const nlohmann::json& v) {
    return v.is_string() ? v.get<std::string>() : v.is_null() ? std::string("&#8212;") : v.dump();
  };
  std::string o = "<section class=\"batch\"><h2>Batch " + Escape(text(b["id"])) + "</h2>";
  o += fmt::format(
      "<p>{}{} units, started {}: {} passed, {} waiting, {} held{}. This report is of {}.</p>",
      fixture ? "Fixture " + Escape(b["fixture"].get<std::string>()) + ", " : std::string(),
      b["units"].size(), Escape(text(b.value("started", nlohmann::json()))), b.value("passed", 0),
      b.value("waiting", 0), b.value("held", 0),
      b.value("seconds_to_last_gate", nlohmann::json()).is_number()
          ? fmt::format("; the last gate after {:.0f} s of table time",
                        b["seconds_to_last_gate"].get<double>())
          : std::string(),
      Escape(device));
  o += "<table><tr><th>slot</th><th>device</th><th>serial</th><th>state</th><th>poses</th>"
       "<th>time to its gates</th><th>why</th></tr>";
  for (const auto& u : b["units"]) {
    if (!u.is_object()) continue;
    const std::string state = u.value("state", "");
    const std::string name = u.value("device", "");
    o += fmt::format(
        "<tr{}><td>{}</td><td>{}</td><td>{}</td><td class=\"{}\">{}</td><td>{}</td><td>{}</td>"
        "<td>{}</td></tr>",
        name == device ? " style=\"font-weight:bold\"" : "",
        Escape(text(u.value("slot", nlohmann::json()))), Escape(name),
        Escape(text(u.value("serial", nlohmann::json()))), state == "passed" ? "pass" : "fail",
        Escape(state), u.value("poses", 0),
        u.value("seconds", nlohmann::json()).is_number()
            ? fmt::format("{:.0f} s", u["seconds"].get<double>())
            : std::string("&#8212;"),
        Escape(u.value("why", "")));
  }
  return o + "</table></section>\n";
}

}  // namespace

bool RenderReportHtml(const std::vector<nlohmann::json>& calibrations, const ReportOptions& options,
                      std::string* html, std::string* error) {
  if (calibrations.empty()) {
    if (error) *error = "no calibration to report";
    return false;
  }
  // Calibrations without a turntable (protocol/free_json.h) are re-fitted and shown as `turncal
  // free` shows them: alone, or after the turntable's.
  std::vector<nlohmann::json> pose_docs, free_docs, thermal_docs;
  for (const auto& c : calibrations) {
    (protocol::IsThermalCalibration(c) ? thermal_docs
     : protocol::IsFreeCalibration(c)  ? free_docs
                                       : pose_docs)
        .push_back(c);
  }
  // Calibrations over temperature: a section each, after the others (or alone).
  std::string thermal_body;
  for (const auto& c : thermal_docs) {
    const std::string device = calibrations[0].value("device", "");
    if (c.value("device", "") != device) {
      if (error) {
        *error = fmt::format(
            "the calibrations are of two devices, '{}' and '{}': one report is for one device",
            device, c.value("device", ""));
      }
      return false;
    }
    std::string section;
    if (!ThermalSectionHtml(c, &section, error)) return false;
    thermal_body += section;
  }
  if (pose_docs.empty() && free_docs.empty()) {
    const std::string device = thermal_docs[0].value("device", "");
    std::string o = PageStart(device, options);
    o += "</header>\n" + BatchHtml(options.batch, device) + thermal_body +
         DeviceWritesHtml(options.device_writes);
    o += "</body>\n</html>\n";
    *html = std::move(o);
    return true;
  }
  std::string free_body;
  if (!free_docs.empty()) {
    FreeReportInput in;
    std::string why;
    if (!FreeCalibrationsReport(free_docs, options.source, &in, &why)) {
      if (error) *error = why;
      return false;
    }
    const std::string device = free_docs[0].value("device", "");
    for (const auto& c : pose_docs) {
      if (c.value("device", "") != device) {
        if (error) {
          *error = fmt::format(
              "the calibrations are of two devices, '{}' and '{}': one report is "
              "for one device",
              device, c.value("device", ""));
        }
        return false;
      }
    }
    if (pose_docs.empty()) {
      if (!options.generated_utc.empty()) {
        in.lines.insert(in.lines.begin(), "generated " + options.generated_utc);
      }
      *html = FreeReportHtml(in);
      if (const std::string batch = BatchHtml(options.batch, device); !batch.empty()) {
        const std::size_t header = html->find("</header>");
        if (header != std::string::npos) html->insert(header + 9, "\n" + batch);
      }
      if (!thermal_body.empty()) {
        const std::size_t end = html->rfind("</body>");
        html->insert(end == std::string::npos ? html->size() : end, thermal_body);
      }
      return true;
    }
    free_body =
        "<section><h2>" + Escape(in.title) + "</h2>\n" + FreeReportBody(in) + "</section>\n";
  }
  std::vector<protocol::CalibrationDocument> docs(pose_docs.size());
  for (std::size_t i = 0; i < pose_docs.size(); ++i) {
    if (!protocol::ParseCalibrationDocument(pose_docs[i], &docs[i], error)) return false;
    if (docs[i].device != docs[0].device) {
      if (error) {
        *error = fmt::format(
            "the calibrations are of two devices, '{}' and '{}': one report "
            "is for one device",
            docs[0].device, docs[i].device);
      }
      return false;
    }
    for (std::size_t k = 0; k < i; ++k) {
      if (docs[k].model == docs[i].model) {
        if (error) *error = fmt::format("two calibrations of {} {}", docs[i].device, docs[i].model);
        return false;
      }
    }
  }
  std::sort(docs.begin(), docs.end(),
            [](const auto& a, const auto& b) { return ModelRank(a.model) < ModelRank(b.model); });
  const std::string& device = docs[0].device;
  std::string o = PageStart(device, options);
  nlohmann::json identity;
  for (const auto& d : docs) {
    if (d.identity.is_object() && !d.identity.empty()) identity = d.identity;
  }
  o += IdentityHtml(identity);
  o += SummaryHtml(docs);
  o += "</header>\n";
  o += BatchHtml(options.batch, device);
  for (const auto& d : docs) {
    o += ModelSection(d);
    o += DriftSectionHtml(DriftSummary(options.drift, d.model), d.model);
  }
  o += TriadAngleHtml(docs);
  o += DeviceWritesHtml(options.device_writes);
  o += free_body;
  o += thermal_body;
  o += "</body>\n</html>\n";
  *html = std::move(o);
  return true;
}

}  // namespace turncal::report
