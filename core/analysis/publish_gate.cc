#include "core/analysis/publish_gate.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace turncal {

bool GateTolerancesForClass(const std::string& sensor_class, GateTolerances* out) {
  GateTolerances t;
  if (sensor_class == "industrial") {
    *out = t;
    return true;
  }
  if (sensor_class == "consumer") {
    t.scale_factor = 1000e-6;
    t.angle_rad = 0.1 * M_PI / 180;
    t.acceleration_mps2 = 2e-3 * 9.80665;
    t.gain = 2e-3;
    t.field = 2e-3;
    t.angular_rate_radps = 100.0 * M_PI / 180 / 3600;
    t.g_sensitivity = 200.0 * M_PI / 180 / 3600 / 9.80665;
    t.second_order = 1000e-6 / 9.80665;
    *out = t;
    return true;
  }
  return false;
}

bool GateDefaultsForClass(const std::string& sensor_class, GateOptions* out) {
  if (!GateTolerancesForClass(sensor_class, &out->tolerances)) return false;
  out->min_dof = sensor_class == "consumer" ? 6 : 3;
  return true;
}

bool GateOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& message) {
    if (error) *error = message;
    return false;
  };
  const GateTolerances& t = tolerances;
  for (double v : {t.scale_factor, t.angle_rad, t.acceleration_mps2, t.gain, t.field,
                   t.angular_rate_radps, t.g_sensitivity, t.second_order}) {
    if (!(v > 0) || !std::isfinite(v)) return fail("every tolerance must be finite and > 0");
  }
  for (const auto& [name, v] : parameter_tolerance) {
    if (!(v > 0) || !std::isfinite(v)) {
      return fail("the tolerance of '" + name + "' must be finite and > 0");
    }
  }
  if (!(min_p_value >= 0 && min_p_value < 1)) return fail("min_p_value must be in [0, 1)");
  if (min_dof < 0) return fail("min_dof must be >= 0");
  if (!(max_normalized_residual > 0)) return fail("max_normalized_residual must be > 0");
  return true;
}

std::vector<int> GatedParameters(const MeasurementModel& model) {
  std::vector<int> gated;
  const bool table_frame = model.corrected_frame() == OutputFrame::kTable;
  for (int i = 0; i < model.num_parameters(); ++i) {
    const ParameterKind kind = model.parameters()[i].kind;
    if (kind == ParameterKind::kSensor || (kind == ParameterKind::kMounting && table_frame)) {
      gated.push_back(i);
    }
  }
  return gated;
}

double ToleranceFor(const ParameterInfo& parameter, const GateOptions& options) {
  if (auto it = options.parameter_tolerance.find(parameter.name);
      it != options.parameter_tolerance.end()) {
    return it->second;
  }
  const GateTolerances& t = options.tolerances;
  switch (parameter.unit) {
    case ParameterUnit::kScaleFactor:
      return t.scale_factor;
    case ParameterUnit::kAngle:
      return t.angle_rad;
    case ParameterUnit::kAcceleration:
      return t.acceleration_mps2;
    case ParameterUnit::kGain:
      return t.gain;
    case ParameterUnit::kField:
      return t.field;
    case ParameterUnit::kAngularRate:
      return t.angular_rate_radps;
    case ParameterUnit::kGSensitivity:
      return t.g_sensitivity;
    case ParameterUnit::kSecondOrder:
      return t.second_order;
  }
  return t.gain;
}

double FreeToleranceFor(const ParameterInfo& parameter, const GateOptions& options,
                        ParameterInfo* judged_as) {
  ParameterInfo as = parameter;
  const bool gain_k = parameter.unit == ParameterUnit::kGain && parameter.name.size() == 2 &&
                      parameter.name[0] == 'k';
  if (gain_k) as.unit = ParameterUnit::kScaleFactor;
  if (judged_as) *judged_as = as;
  if (parameter.kind != ParameterKind::kSensor &&
      !options.parameter_tolerance.count(parameter.name)) {
    return -1.0;
  }
  return ToleranceFor(as, options);
}

std::vector<std::string> PrecisionShortfalls(const MeasurementModel& model,
                                             const Eigen::VectorXd& sigma,
                                             const GateOptions& options,
                                             const std::vector<bool>* skip) {
  std::vector<std::string> out;
  for (int i : GatedParameters(model)) {
    if (skip && (*skip)[static_cast<std::size_t>(i)]) continue;
    const ParameterInfo& p = model.parameters()[i];
    const double tolerance = ToleranceFor(p, options);
    if (!(sigma[i] <= tolerance)) {
      out.push_back(fmt::format("{}: sigma {} exceeds the tolerance {}", p.name,
                                FormatSigma(p, sigma[i]), FormatSigma(p, tolerance)));
    }
  }
  return out;
}

void AddFitReasons(double chi2, int dof, double p_value, const FitCheck& fit,
                   const std::vector<PoseResidual>& residuals, SensorKind sensor,
                   const GateOptions& options, const std::string& cause, GateResult* result) {
  if (dof < options.min_dof) {
    result->reasons.push_back(fmt::format(
        "{} degrees of freedom: chi^2 cannot test the noise model until there are {} (add poses)",
        dof, options.min_dof));
  } else if (p_value < options.min_p_value) {
    result->reasons.push_back(fmt::format(
        "chi^2 = {:.1f} on {} dof (p = {:.2g} < {:.2g}): the noise model does not "
        "explain the data ({})",
        chi2, dof, p_value, options.min_p_value, fit.cause.empty() ? cause : fit.cause));
  } else if (fit.verdict != FitVerdict::kOk) {
    // The other tail, or an upper tail between the fit check's level and the gate's: a note,
    // since the sigma are then too large (the gate errs towards waiting), not too small.
    result->notes.push_back("fit check: " + fit.Message(ToString(sensor)));
  }
  for (std::size_t i = 0; i < residuals.size(); ++i) {
    const double r = residuals[i].normalized;
    if (r > options.max_normalized_residual) {
      result->reasons.push_back(fmt::format("pose {} has normalised residual {:.1f} > {:.1f}", i, r,
                                            options.max_normalized_residual));
    }
  }
}

GateResult EvaluateGate(const MeasurementModel& model, const Estimate& estimate,
                        const DataReport& data, const GateOptions& options) {
  GateResult result;
  auto& reasons = result.reasons;
  if (!estimate.ok) {
    reasons.push_back("no estimate: " + estimate.error);
    return result;
  }
  if (estimate.termination != "CONVERGENCE") {
    reasons.push_back("the solver did not converge (" + estimate.termination + ")");
  }
  const auto& params = model.parameters();
  const std::vector<int> gated = GatedParameters(model);
  auto is_gated = [&](int j) { return std::find(gated.begin(), gated.end(), j) != gated.end(); };

  // 1. Every direction the correction depends on is observable.
  std::vector<bool> missing(params.size(), false), undetermined(params.size(), false);
  for (const auto& d : data.analysis.null) {
    const Eigen::VectorXd v = OutsideGauge(model, data.theta, d.scaled);
    if (v.norm() < 1e-6) continue;
    for (int j = 0; j < static_cast<int>(params.size()); ++j) {
      if (std::abs(v[j]) <= kUndeterminedComponent) continue;
      (is_gated(j) ? missing : undetermined)[j] = true;
    }
  }
  for (int j = 0; j < static_cast<int>(params.size()); ++j) {
    if (missing[j]) result.missing.push_back(params[j].name);
  }
  if (!result.missing.empty()) {
    std::string names, directions;
    for (const auto& n : result.missing) names += (names.empty() ? "" : " ") + n;
    for (const auto& d : data.analysis.null) {
      if (OutsideGauge(model, data.theta, d.scaled).norm() >= 1e-6) {
        directions += (directions.empty() ? "" : "; ") + d.text;
      }
    }
    reasons.push_back(fmt::format(
        "rank {} of {}: the poses leave these combinations undetermined: {}; so the correction's "
        "{} parameter(s) are not determined: {}",
        data.analysis.rank, data.expected_rank, directions, result.missing.size(), names));
    for (const auto& finding : data.diversity.findings) reasons.push_back("poses: " + finding);
  }
  const Eigen::MatrixXd gauge = GaugeDirections(model, data.theta);
  for (Eigen::Index c = 0; c < gauge.cols(); ++c) {
    std::string touched;
    for (int j : gated) {
      if (std::abs(gauge(j, c)) > 1e-12) touched += (touched.empty() ? "" : " ") + params[j].name;
    }
    if (touched.empty()) continue;
    const std::string text = fmt::format(
        "the correction depends on gauge direction {} of {}, which no turntable data can "
        "resolve ({}); it is published in the gauge '{}'",
        c + 1, model.name(), touched, data.gauge);
    if (options.accept_gauge_dependent_correction) {
      result.notes.push_back(text);
    } else {
      reasons.push_back(text +
                        " only when accept_gauge_dependent_correction is set (or use mag13)");
    }
  }

  // 2. Precision of the gated parameters (the estimate's sigma, inflated when chi^2 says so); the
  // undetermined ones are already reported.
  for (auto& r : PrecisionShortfalls(model, estimate.sigma, options, &missing)) {
    reasons.push_back(std::move(r));
  }

  // 3. chi^2 consistent with the noise; 4. no extreme pose.
  AddFitReasons(estimate.chi2, estimate.dof, estimate.p_value, estimate.fit, estimate.residuals,
                model.sensor(), options,
                "bias drift between poses, a pose that is not what was commanded, or the wrong "
                "model",
                &result);

  // Installation parameters: reported, not gated.
  for (int j = 0; j < static_cast<int>(params.size()); ++j) {
    if (is_gated(j)) continue;
    if (undetermined[j]) {
      result.notes.push_back(fmt::format("{} ({}) is not determined by these poses; not gated",
                                         params[j].name, ToString(params[j].kind)));
    } else {
      // Value and sigma in the same display unit (degrees for beta and eps, mG for dB).
      const DisplayQuantity value = ForDisplay(params[j], estimate.theta[j], /*is_sigma=*/false);
      result.notes.push_back(fmt::format("{} ({}) = {:.6g} +- {}; not gated", params[j].name,
                                         ToString(params[j].kind), value.value,
                                         FormatSigma(params[j], estimate.sigma[j])));
    }
  }
  result.pass = reasons.empty();
  return result;
}

}  // namespace turncal
