#include "daemon/station/free_pipeline.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/sequencing/stillness.h"
#include "daemon/station/model_pipeline.h"
#include "daemon/station/station.h"
#include "drivers/transport/transport.h"
#include "protocol/calibration_json.h"
#include "protocol/free_json.h"

namespace turncal::daemon {

FreeContext FreeContextFor(const StationOptions& options, const SensorClass& sensor) {
  FreeContext c;
  const ReferenceVectors& ref = options.context.reference;
  c.gravity_mps2 = ref.g_ned.norm();
  c.field_magnitude = options.free.field_known ? ref.B_ned.norm() : 0.0;
  c.latitude_deg = ref.latitude_deg;
  const double horizontal = ref.B_ned.head<2>().norm();
  c.dip_deg = std::atan2(ref.B_ned.z(), horizontal) * 180 / M_PI;
  if (options.drift_model) {
    c.acc_drift = DriftForClass(sensor, SensorKind::kAccelerometer);
    c.mag_drift = DriftForClass(sensor, SensorKind::kMagnetometer);
    c.gyr_drift = DriftForClass(sensor, SensorKind::kGyroscope);
  } else {
    c.acc_offset_sigma = sensor.acc_bias_instability;
    c.mag_offset_sigma = sensor.mag_bias_instability;
    c.gyr_offset_sigma = sensor.gyr_bias_instability;
  }
  return c;
}

FreeCalibratorOptions FreeOptionsFor(const StationOptions& options, const GateOptions& gate) {
  FreeCalibratorOptions o;
  o.min_coverage = options.free.min_coverage_percent / 100;
  o.precision = gate;
  return o;
}

const char* FreeOutputFrame(const std::string& model) {
  return model == "magellipsoid" || model == "magsphere" ? "magnetometer" : "accelerometer";
}

int MovesUsed(const FreeEstimate& estimate) {
  return static_cast<int>(
      std::count_if(estimate.terms.begin(), estimate.terms.end(),
                    [](const FreeTermResidual& t) { return t.kind == "direction"; }));
}

void FreeUpdate::Run(const std::vector<std::string>& configured,
                     const std::vector<FreeInterval>& still, const MotionCollector* collector,
                     const MotionOptions& motion_options, const FreeContext& context,
                     const FreeCalibratorOptions& options) {
  intervals = still.size();
  auto all = std::make_shared<std::vector<FreeInterval>>(still);
  if (collector) {
    motion = collector->Select(still, motion_options);
    all->insert(all->end(), motion->points.begin(), motion->points.end());
  }
  data = all;
  models = configured.empty() ? DefaultFreeModels(*all) : configured;
  results.clear();
  FreeCalibratorOptions with_noise = options;
  if (motion) with_noise.motion_noise_dof = motion->sigma_dof;
  if (!CalibrateFreeModels(models, *all, context, with_noise, &results, &error)) return;
  advice = NextOrientations(results, *all, context);
}

nlohmann::json FreeMotionState::Json() const {
  nlohmann::json j = {{"enabled", enabled},
                      {"values", kept},
                      {"samples_with_mag", collector.samples_with_mag()},
                      {"held", collector.held()},
                      {"thinned", collector.thinned()}};
  if (last) {
    j["points"] = last->points.size();
    j["in_intervals"] = last->in_intervals;
    j["in_noise_measurement"] = last->in_noise_measurement;
    j["decimated"] = last->decimated;
    j["rate_hz"] = last->period_s > 0 ? nlohmann::json(1.0 / last->period_s) : nlohmann::json();
    j["noise_source"] = last->noise_source;
    j["summary"] = last->Summary();
    if (last->bandwidth_hz > 0) {
      j["bandwidth_hz"] = last->bandwidth_hz;
      j["smallest_attenuation"] = last->smallest_attenuation;
    }
  }
  return j;
}

int FreeModelState::triad() const { return TriadOfSensor(sensor); }

void FreeModelState::Apply(int version, const std::string& model, const Eigen::VectorXd& theta,
                           const Eigen::MatrixXd& covariance, const std::string& upstream_model,
                           const Eigen::VectorXd& upstream_theta,
                           const std::optional<TimeWindow>& bias_window,
                           const FreeContext& context) {
  std::string error;
  std::shared_ptr<const FreeModel> m = MakeFreeModel(model, context, &error);
  if (!m || theta.size() != m->num_parameters()) return;
  std::shared_ptr<const FreeModel> up =
      upstream_model.empty() ? nullptr : MakeFreeModel(upstream_model, context, &error);
  applied_version_ = version;
  applied_model = m;
  applied_theta = theta;
  applied_covariance = covariance.rows() == theta.size() ? covariance : Eigen::MatrixXd();
  applied_upstream_model = up && upstream_theta.size() == up->num_parameters() ? up : nullptr;
  applied_upstream_theta = applied_upstream_model ? upstream_theta : Eigen::VectorXd();
  applied_bias_window = bias_window;
  applied_drift = m->sensor() == SensorKind::kAccelerometer ? context.acc_drift
                  : m->sensor() == SensorKind::kGyroscope   ? context.gyr_drift
                                                            : context.mag_drift;
}

bool FreeModelState::ApplyStored(const nlohmann::json& stored, std::string* error) {
  protocol::FreeCalibrationDocument doc;
  if (!protocol::ParseFreeCalibration(stored, &doc, error)) return false;
  Apply(doc.version, doc.model, doc.theta, doc.covariance, doc.upstream_model, doc.upstream_theta,
        doc.bias_window, doc.context);
  if (applied_version_ != doc.version) {
    *error = "the stored calibration's model cannot be made";
    return false;
  }
  active_version_ = applied_version_;
  return true;
}

void FreeModelState::ApplyResult(const FreeContext& context) {
  const FreeEstimate& fe = result.estimate;
  Apply(active_version_, result.model, fe.estimate.theta, fe.estimate.covariance,
        upstream ? upstream->model : std::string(),
        upstream ? upstream->estimate.estimate.theta : Eigen::VectorXd(), fe.bias_window_host,
        context);
}

bool FreeModelState::Correct(const Sample& sample, double t_s, Eigen::Vector3d* value,
                             std::optional<Eigen::Vector3d>* sigma, const char** frame) const {
  if (applied_version_ <= 0 || !applied_model) return false;
  const int t = triad();
  const Eigen::Vector3d& raw = *RawTriad(sample, t);
  *value = Correct(raw, sample.acc_mps2 ? &*sample.acc_mps2 : nullptr, t_s, sigma);
  *frame = FreeOutputFrame(applied_model->name());
  return true;
}

bool FreeModelState::HasEstimate(std::string* error) const {
  *error = result.estimate.estimate.error;
  return result.estimate.estimate.ok;
}

Activation FreeModelState::Activate(const DevicePipeline& d, const ActivationContext& context,
                                    double t_s) {
  ++active_version_;
  protocol::FreeCalibrationInput in;
  in.device = d.name;
  in.version = active_version_;
  in.result = &result;
  in.upstream = upstream ? &*upstream : nullptr;
  in.advice = advice;
  in.context = owner->context();
  in.options = owner->options();
  in.sensor_class = context.sensor_class;
  if (estimate_data) {
    // The evidence the model used: the samples in motion only for a magnetometer model.
    std::string error;
    auto model = MakeFreeModel(result.model, owner->context(), &error);
    const bool mag = model && model->Needs(SensorKind::kMagnetometer);
    for (const FreeInterval& iv : *estimate_data) {
      if (!iv.in_motion || mag) in.intervals.push_back(iv);
    }
  } else {
    in.intervals.assign(d.records_used.begin(),
                        d.records_used.begin() + static_cast<std::ptrdiff_t>(std::min(
                                                     estimate_intervals, d.records_used.size())));
  }
  in.identity = d.identity;
  Activation a;
  a.document = protocol::FreeCalibrationJson(in);
  a.document["requested"] = requested;
  a.document["time"] = drivers::UtcNowIso8601();
  a.event = {{"class", "CALIBRATION_ACTIVE"},
             {"t", t_s},
             {"device", d.name},
             {"model", requested},
             {"fitted", result.model},
             {"version", active_version_},
             {"poses", result.estimate.intervals},
             {"intervals", result.estimate.intervals},
             {"moves", MovesUsed(result.estimate)}};
  const Estimate& e = result.estimate.estimate;
  a.apply = [this, version = active_version_, model = result.model, theta = e.theta,
             covariance = e.covariance, window = result.estimate.bias_window_host,
             upstream_model = upstream ? upstream->model : std::string(),
             upstream_theta = upstream ? upstream->estimate.estimate.theta : Eigen::VectorXd(),
             context = owner->context()] {
    if (version > applied_version_) {
      Apply(version, model, theta, covariance, upstream_model, upstream_theta, window, context);
    }
  };
  return a;
}

Eigen::Vector3d FreeModelState::Correct(const Eigen::Vector3d& raw, const Eigen::Vector3d* acc_raw,
                                        double t_s, std::optional<Eigen::Vector3d>* sigma) const {
  const int g = applied_model->index_of("g11");
  std::optional<Eigen::Vector3d> force;
  if (g >= 0 && acc_raw && applied_upstream_model) {
    force = applied_upstream_model->Correct(applied_upstream_theta, *acc_raw);
  }
  auto corrected = [&](const Eigen::VectorXd& theta) {
    Eigen::Vector3d r = raw;
    if (force) {
      Eigen::Matrix3d B;
      for (int k = 0; k < 9; ++k) B(k / 3, k % 3) = theta[g + k];
      r -= B * *force;
    }
    return applied_model->Correct(theta, r);
  };
  const Eigen::Vector3d value = corrected(applied_theta);
  if (sigma) {
    sigma->reset();
    const Eigen::Index n = applied_theta.size();
    if (applied_covariance.rows() == n && applied_covariance.allFinite()) {
      Eigen::MatrixXd covariance = applied_covariance;
      // How far the bias may have wandered since the calibration's window.
      if (applied_bias_window && applied_drift.enabled()) {
        const TimeWindow& w = *applied_bias_window;
        const double since_s = t_s >= w.t0_s ? t_s : w.t1_s + 1e9;
        for (const auto& [kind, start] : applied_model->BiasColumns()) {
          if (kind != applied_model->sensor()) continue;
          for (int axis = 0; axis < 3; ++axis) {
            covariance(start + axis, start + axis) += applied_drift.VarianceSince(axis, w, since_s);
          }
        }
      }
      *sigma = PropagatedSigma(corrected, applied_theta, covariance);
    }
  }
  return value;
}

nlohmann::json FreeModelState::PrecisionJson(const GateOptions& gate) const {
  nlohmann::json precision = nlohmann::json::object();
  const Estimate& e = result.estimate.estimate;
  if (!e.ok || e.sigma.size() != static_cast<Eigen::Index>(e.parameters.size())) return precision;
  for (std::size_t p = 0; p < e.parameters.size(); ++p) {
    const double tolerance = FreeToleranceFor(e.parameters[p], gate);
    if (tolerance <= 0) continue;
    const double s = e.sigma[static_cast<Eigen::Index>(p)];
    precision[e.parameters[p].name] = {
        {"sigma", std::isfinite(s) ? nlohmann::json(s) : nlohmann::json()},
        {"tolerance", tolerance}};
  }
  return precision;
}

nlohmann::json FreeModelState::ResultJson() const {
  nlohmann::json j = protocol::FreeResultJson(result, advice);
  j["requested"] = requested;
  if (result.model.empty()) j["model"] = requested;  // not fitted yet
  j["poses"] = result.estimate.intervals;
  j["moves"] = MovesUsed(result.estimate);
  j["upstream"] = upstream ? nlohmann::json(upstream->model) : nlohmann::json();
  j["active_version"] = active_version_;
  j["applied_version"] = applied_version_;
  return j;
}

nlohmann::json FreeModelState::StatusJson() const {
  const FreeEstimate& fe = result.estimate;
  const std::string why =
      fe.estimate.error.empty() ? "no static interval fitted yet" : fe.estimate.error;
  nlohmann::json gate = {
      {"pass", fe.estimate.ok && fe.gate_passed},
      {"reasons",
       fe.estimate.ok ? fe.gate_reasons : std::vector<std::string>{"no estimate: " + why}}};
  return {{"model", result.model.empty() ? requested : result.model},
          {"note", result.note},
          {"poses", fe.intervals},
          {"intervals", fe.intervals},
          {"coverage", fe.coverage.fraction()},
          {"gate", gate},
          {"fit_check", ToString(fe.estimate.fit.verdict)},
          {"advice", advice ? nlohmann::json(advice->text) : nlohmann::json()},
          {"active_version", active_version_},
          {"applied_version", applied_version_}};
}

}  // namespace turncal::daemon
