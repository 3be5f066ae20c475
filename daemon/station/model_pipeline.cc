#include "daemon/station/model_pipeline.h"

#include <algorithm>
#include <cmath>

#include "daemon/station/station.h"
#include "drivers/transport/transport.h"
#include "protocol/calibration_json.h"
#include "protocol/observability_json.h"

namespace turncal::daemon {

ModelPipeline ModelPipeline::Make(const std::string& name, const StationOptions& options,
                                  const SensorClass& sensor) {
  ModelPipeline m;
  std::string error;
  m.model = MakeModel(name, options.context, &error);
  CalibratorOptions co = options.drift_model ? DriftOptionsForClass(*m.model, sensor)
                                             : OptionsForClass(*m.model, sensor);
  // The class's drift (or the one configured) is the prior; the session's poses identify
  // its strength.
  co.identify_drift = options.drift_model && options.identify_drift;
  co.rate_accuracy = options.rate_accuracy;
  m.calibrator = std::make_unique<Calibrator>(co);
  return m;
}

void ModelPipeline::Apply(int version, const Eigen::VectorXd& theta,
                          const Eigen::MatrixXd& covariance,
                          const std::optional<TimeWindow>& bias_window, const BiasDrift& drift) {
  applied_version_ = version;
  applied_theta = theta;
  applied_covariance = covariance;
  applied_bias_window = bias_window;
  applied_drift = drift;
  applied_c = model->Correct(theta, Eigen::Vector3d::Zero());
  for (int i = 0; i < 3; ++i) {
    applied_A.col(i) = model->Correct(theta, Eigen::Vector3d::Unit(i)) - applied_c;
  }
  // Affine when a point away from the probes maps the same both ways.
  const Eigen::Vector3d probe(0.83, -1.37, 2.11);
  const Eigen::Vector3d exact = model->Correct(theta, probe);
  const Eigen::Vector3d affine = applied_A * probe + applied_c;
  applied_affine = exact.allFinite() && (exact - affine).norm() <= 1e-12 * (1.0 + exact.norm());
}

bool ModelPipeline::ApplyStored(const nlohmann::json& stored, std::string* error) {
  if (!stored.contains("version") || !stored["version"].is_number_integer()) {
    error->clear();
    return false;
  }
  active_version_ = stored["version"].get<int>();
  Eigen::VectorXd theta;
  Eigen::MatrixXd covariance;
  if (!protocol::ReadCalibrationValues(*model, stored, &theta, &covariance)) {
    error->clear();
    return false;
  }
  const std::optional<TimeWindow> window = StoredBiasWindow(stored);
  BiasDrift drift;
  if (stored.contains("calibrator") && stored["calibrator"].is_object() &&
      stored["calibrator"].contains("drift")) {
    protocol::ParseBiasDrift(stored["calibrator"]["drift"], &drift);
  }
  Apply(stored["version"].get<int>(), theta, Eigen::MatrixXd(), window, drift);
  if (covariance.size() > 0) applied_covariance = covariance;
  return true;
}

bool ModelPipeline::HasEstimate(std::string* error) const {
  *error = estimate.error;
  return estimate.ok;
}

Activation ModelPipeline::Activate(const DevicePipeline& d, const ActivationContext& context,
                                   double t_s) {
  ++active_version_;
  active = estimate;
  protocol::PoseCalibrationInput in;
  in.device = d.name;
  in.version = active_version_;
  in.model = model.get();
  in.estimate = &estimate;
  in.rank = rank;
  in.gate = gate;
  in.gate_options = d.gate;
  in.calibrator = calibrator->options();
  in.sensor_class = context.sensor_class;
  in.context = context.context;
  in.poses = &d.poses_used;
  in.records = &d.records_used;
  in.count = estimate_poses;
  in.identity = d.identity;
  Activation a;
  a.document = protocol::PoseCalibrationJson(in);
  a.document["time"] = drivers::UtcNowIso8601();
  a.event = {{"class", "CALIBRATION_ACTIVE"},
             {"t", t_s},
             {"device", d.name},
             {"model", model->name()},
             {"version", active_version_},
             {"poses", estimate.poses},
             {"moves", estimate.moves}};
  a.apply = [this, version = active_version_, theta = estimate.theta,
             covariance = estimate.covariance, window = estimate.bias_window,
             drift = estimate.drift] {
    if (version > applied_version_) Apply(version, theta, covariance, window, drift);
  };
  return a;
}

void ModelPipeline::AddAndSolve(const PoseRecord& record, const GateOptions& gate_options,
                                ModelUpdate* job) {
  std::lock_guard lock(*calibrator_mutex);
  job->added = calibrator->add_pose(record, &job->error);
  job->moves_refused = calibrator->moves_refused();
  job->last_move_refusal = calibrator->last_move_refusal();
  if (!job->added) return;
  job->estimate = calibrator->solve();
  if (job->estimate.ok) {
    const DataReport data = AnalyzeData(*model, job->estimate.theta, calibrator->weighted_poses(),
                                        ObservabilityOptions{});
    job->rank = data.analysis.rank;
    job->gate = EvaluateGate(*model, job->estimate, data, gate_options);
  } else {
    job->gate.reasons.push_back("no estimate: " + job->estimate.error);
  }
}

void ModelPipeline::TakeUpdate(const ModelUpdate& job) {
  moves_refused = job.moves_refused;
  last_move_refusal = job.last_move_refusal;
  estimate = job.estimate;
  estimate_poses = job.device_poses;
  rank = job.rank;
  gate = job.gate;
}

nlohmann::json ModelPipeline::EstimateEventJson(const GateOptions& gate_options) const {
  return {{"poses", estimate.poses},
          {"moves", estimate.moves},
          {"summary", estimate.BriefReport()},
          {"precision", PrecisionJson(gate_options)}};
}

void ModelPipeline::ApplyCurrentEstimate() {
  active = estimate;
  Apply(active_version_, estimate.theta, estimate.covariance, estimate.bias_window, estimate.drift);
}

std::optional<Eigen::Vector3d> CorrectionSigma(
    const MeasurementModel& model, const Eigen::VectorXd& theta, Eigen::MatrixXd covariance,
    const Eigen::Vector3d& raw, const Eigen::Vector3d& bias_drift_var, const Eigen::Vector3d* f_q) {
  const Eigen::Index n = theta.size();
  if (covariance.rows() != n || covariance.cols() != n || !covariance.allFinite()) {
    return std::nullopt;
  }
  const auto& params = model.parameters();
  for (Eigen::Index k = 0; k < n; ++k) {
    const std::string& name = params[static_cast<std::size_t>(k)].name;
    if (name == "bx" || name == "by" || name == "bz")
      covariance(k, k) += bias_drift_var[name[1] - 'x'];
  }
  const auto corrected = [&](const Eigen::VectorXd& at) {
    return model.Correct(at, WithoutGSensitivity(model, at, raw, f_q));
  };
  return PropagatedSigma(corrected, theta, covariance);
}

Eigen::Vector3d WithoutGSensitivity(const MeasurementModel& model, const Eigen::VectorXd& theta,
                                    const Eigen::Vector3d& raw, const Eigen::Vector3d* f_q) {
  const int g = f_q ? model.index_of("Bg_xx") : -1;
  if (g < 0) return raw;
  Eigen::Matrix3d B;
  for (int k = 0; k < 9; ++k) B(k / 3, k % 3) = theta[g + k];
  return raw - B * *f_q;
}

std::optional<Eigen::Vector3d> GyroSpecificForce(const MeasurementModel& model, int triad,
                                                 const Sample& sample) {
  if (triad != kTriadGyr || !sample.acc_mps2) return std::nullopt;
  return Eigen::Vector3d(model.context().mounting.transpose() * *sample.acc_mps2);
}

std::optional<TimeWindow> StoredBiasWindow(const nlohmann::json& stored) {
  TimeWindow w;
  if (stored.contains("bias_window") && protocol::ParseTimeWindow(stored["bias_window"], &w)) {
    return w;
  }
  return std::nullopt;
}

Eigen::Vector3d PropagatedSigma(
    const std::function<Eigen::Vector3d(const Eigen::VectorXd&)>& corrected,
    const Eigen::VectorXd& theta, const Eigen::MatrixXd& covariance) {
  const Eigen::Index n = theta.size();
  Jacobian3 jacobian(3, n);
  Eigen::VectorXd t = theta;
  for (Eigen::Index k = 0; k < n; ++k) {
    const double h = 1e-6 * std::max(1.0, std::abs(theta[k]));
    t[k] = theta[k] + h;
    const Eigen::Vector3d up = corrected(t);
    t[k] = theta[k] - h;
    const Eigen::Vector3d down = corrected(t);
    t[k] = theta[k];
    jacobian.col(k) = (up - down) / (2 * h);
  }
  const Eigen::Matrix3d c = jacobian * covariance * jacobian.transpose();
  return c.diagonal().cwiseMax(0.0).cwiseSqrt();
}

int ModelPipeline::triad() const { return TriadOfSensor(model->sensor()); }

const TriadStats* ModelPipeline::TriadOf(const PoseRecord& record) const {
  return TriadFor(model->sensor(), record);
}

Eigen::Vector3d ModelPipeline::Correct(const Eigen::Vector3d& raw_in, double t_s,
                                       std::optional<Eigen::Vector3d>* sigma,
                                       const Eigen::Vector3d* f_q) const {
  // The g-sensitivity's share comes off the raw rate first; the rest of the correction is the
  // model's affine map (Correct with no force).
  const Eigen::Vector3d raw = WithoutGSensitivity(*model, applied_theta, raw_in, f_q);
  const Eigen::Vector3d value = applied_affine ? Eigen::Vector3d(applied_A * raw + applied_c)
                                               : model->Correct(applied_theta, raw);
  if (sigma) {
    const Eigen::Vector3d drift_var = DriftVarianceSince(t_s);
    *sigma = CorrectionSigma(*model, applied_theta, applied_covariance, raw_in, drift_var, f_q);
  }
  return value;
}

Eigen::Vector3d ModelPipeline::DriftVarianceSince(double t_s) const {
  Eigen::Vector3d drift_var = Eigen::Vector3d::Zero();
  if (applied_bias_window && applied_drift.enabled()) {
    const TimeWindow& w = *applied_bias_window;
    // A clock before the calibration's (the host restarted since): the time since is unknown,
    // so the wander's long-term limit (infinite for a random walk).
    const double since_s = t_s >= w.t0_s ? t_s : w.t1_s + 1e9;
    for (int axis = 0; axis < 3; ++axis) {
      drift_var[axis] = applied_drift.VarianceSince(axis, w, since_s);
    }
  }
  return drift_var;
}

bool ModelPipeline::Correct(const Sample& sample, double t_s, Eigen::Vector3d* value,
                            std::optional<Eigen::Vector3d>* sigma, const char** frame) const {
  if (applied_version_ <= 0) return false;
  const int t = triad();
  const Eigen::Vector3d& raw = *RawTriad(sample, t);
  const std::optional<Eigen::Vector3d> f_q = GyroSpecificForce(*model, t, sample);
  *value = Correct(raw, t_s, sigma, f_q ? &*f_q : nullptr);
  *frame = ToString(model->corrected_frame());
  return true;
}

nlohmann::json ModelPipeline::PrecisionJson(const GateOptions& gate_options) const {
  nlohmann::json precision = nlohmann::json::object();
  if (estimate.ok && estimate.sigma.size() == model->num_parameters()) {
    const auto& params = model->parameters();
    for (int j : GatedParameters(*model)) {
      const double sigma = estimate.sigma[j];
      precision[params[static_cast<std::size_t>(j)].name] = {
          {"sigma", std::isfinite(sigma) ? nlohmann::json(sigma) : nlohmann::json()},
          {"tolerance", ToleranceFor(params[static_cast<std::size_t>(j)], gate_options)}};
    }
  }
  return precision;
}

nlohmann::json ModelPipeline::StatusJson() const {
  const CalibratorOptions& co = calibrator->options();
  return {{"poses", estimate.poses},
          {"moves", estimate.moves},
          {"moves_refused", moves_refused},
          {"last_move_refusal", last_move_refusal},
          {"gate", ToJson(gate)},
          {"fit_check", ToString(estimate.fit.verdict)},
          {"noise_model", co.drift.enabled()
                              ? protocol::ToJson(estimate.ok ? estimate.drift : co.drift)
                              : nlohmann::json{{"pose_offset_sigma", co.pose_offset_sigma}}},
          {"drift_scale", estimate.ok && co.identify_drift ? protocol::DriftScaleJson(estimate)
                                                           : nlohmann::json()},
          {"active_version", active_version_},
          {"applied_version", applied_version_}};
}

nlohmann::json ModelPipeline::ResultJson() const {
  const Estimate& e = estimate;
  return {{"ok", e.ok},
          {"poses", e.poses},
          {"moves", e.moves},
          {"params", protocol::ParamsJson(e)},
          {"rank", rank},
          {"chi2", e.chi2},
          {"dof", e.dof},
          {"p_value", e.p_value},
          {"fit_check", protocol::ToJson(e.fit, model->sensor())},
          {"drift_scale", e.ok && calibrator->options().identify_drift ? protocol::DriftScaleJson(e)
                                                                       : nlohmann::json()},
          {"bias_window", e.bias_window ? protocol::ToJson(*e.bias_window) : nlohmann::json()},
          {"gauge", e.gauge},
          {"warnings", e.warnings},
          {"gate", ToJson(gate)},
          {"active_version", active_version_}};
}

}  // namespace turncal::daemon
