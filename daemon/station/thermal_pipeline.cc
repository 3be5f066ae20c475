#include "daemon/station/thermal_pipeline.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <mutex>

#include "daemon/station/station.h"
#include "drivers/transport/transport.h"
#include "protocol/calibration_json.h"
#include "protocol/observability_json.h"
#include "protocol/thermal_json.h"

namespace turncal::daemon {

namespace {
constexpr const char* kSuffix = "@T";
}  // namespace

bool IsThermalModelName(const std::string& name, std::string* base) {
  const std::size_t n = std::char_traits<char>::length(kSuffix);
  if (name.size() <= n || name.compare(name.size() - n, n, kSuffix) != 0) return false;
  if (base) *base = name.substr(0, name.size() - n);
  return true;
}

std::unique_ptr<ModelPipeline> MakePoseModel(const std::string& name, const StationOptions& options,
                                             const SensorClass& sensor) {
  std::string base;
  if (IsThermalModelName(name, &base)) {
    return std::make_unique<ThermalModelPipeline>(ModelPipeline::Make(base, options, sensor),
                                                  options);
  }
  return std::make_unique<ModelPipeline>(ModelPipeline::Make(name, options, sensor));
}

ThermalModelPipeline::ThermalModelPipeline(ModelPipeline base, const StationOptions& options)
    : ModelPipeline(std::move(base)) {
  thermal_name = model->name() + kSuffix;
  fit_options = options.thermal.fit;
  gate_options = options.thermal.gate;
  max_pose_span_c = options.thermal.max_pose_span_c;
  // Over temperature an isothermal fit's residuals hold the temperature dependence: it would
  // take that for drift. The class's drift (or the one configured) is the thermal fit's.
  fit_calibrator = calibrator->options();
  fit_calibrator.identify_drift = false;
  calibrator = std::make_unique<Calibrator>(fit_calibrator);
}

void ThermalModelPipeline::AddAndSolve(const PoseRecord& record, const GateOptions& gate_opts,
                                       ModelUpdate* job) {
  if (!record.temp_c || !std::isfinite(*record.temp_c)) {
    job->added = false;
    job->error =
        "the pose has no temperature: a calibration over temperature needs the device's "
        "temperature channel (MIP temperature statistics, Xbus 0x0810); the pose stays in the "
        "journal";
    return;
  }
  // A temperature that jumped within the window (a glitch of the channel) makes the pose's mean
  // temperature meaningless: refused, with the reason.
  if (record.temp_spread &&
      record.temp_spread->max_c - record.temp_spread->min_c > max_pose_span_c) {
    job->added = false;
    job->error = fmt::format(
        "the pose's temperature spans {:.2f} .. {:.2f} degC within its window (more than {:.1f} "
        "degC: the die still moving after a step of the chamber, or a jump in the temperature "
        "channel?); the pose stays in the journal",
        record.temp_spread->min_c, record.temp_spread->max_c, max_pose_span_c);
    return;
  }
  std::lock_guard lock(*calibrator_mutex);
  // The planner's isothermal calibrator holds the pose (it is not solved: over temperature its
  // estimate means nothing, and the planner linearises at the model's nominal).
  job->added = calibrator->add_pose(record, &job->error);
  if (!job->added) return;
  records.push_back(record);
  // The fit costs O(poses^3) (core/estimation/gls_whitening.h): after the first 30 poses it is
  // repeated once the poses have grown by a tenth, and at the end of the input (SolvePending).
  const std::size_t n = records.size();
  if (n > 30 && n < next_fit_at_) {
    job->solved = false;
    pending_ = true;
    return;
  }
  Fit(gate_opts, job);
}

void ThermalModelPipeline::Fit(const GateOptions& gate_opts, ModelUpdate* job) {
  const std::size_t n = records.size();
  next_fit_at_ = std::max(n + 1, static_cast<std::size_t>(std::ceil(1.1 * static_cast<double>(n))));
  fitted_ = n;
  pending_ = false;
  job->thermal = CalibrateOverTemperature(fit_calibrator, records, fit_options);
  job->rank = job->thermal.rank;
  job->gate = EvaluateThermalGate(*model, job->thermal, gate_opts, gate_options);
  job->estimate.bias_window = TimeWindow{records.back().t_start_s, records.back().t_end_s};
}

bool ThermalModelPipeline::HasPending() const { return pending_; }

void ThermalModelPipeline::SolvePending(const GateOptions& gate_opts, ModelUpdate* job) {
  std::lock_guard lock(*calibrator_mutex);
  if (records.size() > fitted_) {
    Fit(gate_opts, job);
  } else {
    job->solved = false;  // a fit since the request took them
  }
}

void ThermalModelPipeline::TakeUpdate(const ModelUpdate& job) {
  if (!job.solved) return;  // the latest fit stays
  ModelPipeline::TakeUpdate(job);
  thermal = job.thermal;
}

nlohmann::json ThermalModelPipeline::PrecisionJson(const GateOptions& gate_opts) const {
  nlohmann::json precision = nlohmann::json::object();
  for (const ThermalPrecision& p :
       WorstPrecisionOverRange(*model, thermal, gate_opts, gate_options.grid_points)) {
    precision[p.name] = {
        {"sigma", std::isfinite(p.sigma) ? nlohmann::json(p.sigma) : nlohmann::json()},
        {"tolerance", p.tolerance},
        {"at_c", p.at_c}};
  }
  return precision;
}

nlohmann::json ThermalModelPipeline::EstimateEventJson(const GateOptions& gate_opts) const {
  return {
      {"poses", thermal.poses},
      {"moves", 0},
      {"summary", thermal.ok ? thermal.BriefReport() : "no estimate: " + thermal.error},
      {"range_c", thermal.ok ? nlohmann::json{thermal.t_min_c, thermal.t_max_c} : nlohmann::json()},
      {"precision", PrecisionJson(gate_opts)}};
}

void ThermalModelPipeline::ApplyThermal(int version, const ThermalEstimate& e,
                                        const std::optional<TimeWindow>& window) {
  applied_version_ = version;
  applied = e;
  applied_theta = e.ThetaAt(e.basis.t0_c);
  applied_covariance = e.covariance.size() > 0 ? e.CovarianceAt(e.basis.t0_c) : Eigen::MatrixXd();
  applied_bias_window = window;
  applied_drift = fit_calibrator.drift;
  applied_affine = false;
}

void ThermalModelPipeline::ApplyCurrentEstimate() {
  active_thermal = thermal;
  ApplyThermal(active_version_, thermal, estimate.bias_window);
}

double ThermalModelPipeline::EvaluationTemperature(const Sample& sample, const char** flag) const {
  *flag = nullptr;
  if (!sample.temp_c || !std::isfinite(*sample.temp_c)) {
    *flag = "no_temperature";
    return applied.basis.t0_c;
  }
  const double t = *sample.temp_c;
  if (t < applied.t_min_c) {
    *flag = "below_range";
    return applied.t_min_c;
  }
  if (t > applied.t_max_c) {
    *flag = "above_range";
    return applied.t_max_c;
  }
  return t;
}

const char* ThermalModelPipeline::TemperatureFlag(const Sample& sample) const {
  if (applied_version_ <= 0 || !applied.ok) return nullptr;
  const char* flag = nullptr;
  EvaluationTemperature(sample, &flag);
  return flag;
}

bool ThermalModelPipeline::Correct(const Sample& sample, double t_s, Eigen::Vector3d* value,
                                   std::optional<Eigen::Vector3d>* sigma,
                                   const char** frame) const {
  if (applied_version_ <= 0 || !applied.ok) return false;
  const char* flag = nullptr;
  const double temp_c = EvaluationTemperature(sample, &flag);
  if (flag) {
    if (flag[0] == 'b') ++samples_below;
    if (flag[0] == 'a') ++samples_above;
    if (flag[0] == 'n') ++samples_without_temperature;
    if (sample.temp_c) last_outside_c = *sample.temp_c;
  }
  const int t = triad();
  const Eigen::Vector3d& raw_in = *RawTriad(sample, t);
  const std::optional<Eigen::Vector3d> f_q = GyroSpecificForce(*model, t, sample);
  const Eigen::VectorXd theta = applied.ThetaAt(temp_c);
  *value = model->Correct(theta, WithoutGSensitivity(*model, theta, raw_in, f_q ? &*f_q : nullptr));
  if (sigma) {
    *sigma = applied.covariance.size() > 0
                 ? CorrectionSigma(*model, theta, applied.CovarianceAt(temp_c), raw_in,
                                   DriftVarianceSince(t_s), f_q ? &*f_q : nullptr)
                 : std::nullopt;
  }
  *frame = ToString(model->corrected_frame());
  return true;
}

bool ThermalModelPipeline::ApplyStored(const nlohmann::json& stored, std::string* error) {
  if (!stored.contains("version") || !stored["version"].is_number_integer()) {
    error->clear();
    return false;
  }
  active_version_ = stored["version"].get<int>();
  ThermalEstimate e;
  if (!protocol::ReadThermalEstimate(*model, stored, &e, error)) return false;
  ApplyThermal(active_version_, e, StoredBiasWindow(stored));
  return true;
}

bool ThermalModelPipeline::HasEstimate(std::string* error) const {
  *error = thermal.error;
  return thermal.ok;
}

Activation ThermalModelPipeline::Activate(const DevicePipeline& d, const ActivationContext& context,
                                          double t_s) {
  ++active_version_;
  active_thermal = thermal;
  std::vector<PoseRecord> fitted;
  {
    std::lock_guard lock(*calibrator_mutex);  // the worker may be adding a later pose
    const auto n = std::min<std::size_t>(records.size(), static_cast<std::size_t>(thermal.poses));
    fitted.assign(records.begin(), records.begin() + static_cast<std::ptrdiff_t>(n));
  }
  protocol::ThermalCalibrationInput in;
  in.device = d.name;
  in.name = thermal_name;
  in.version = active_version_;
  in.model = model.get();
  in.estimate = &thermal;
  in.gate = gate;
  in.gate_options = d.gate;
  in.calibrator = fit_calibrator;
  in.sensor_class = context.sensor_class;
  in.context = context.context;
  in.records = &fitted;
  in.identity = d.identity;
  Activation a;
  a.document = protocol::ThermalCalibrationJson(in);
  a.document["time"] = drivers::UtcNowIso8601();
  a.document["bias_window"] =
      estimate.bias_window ? protocol::ToJson(*estimate.bias_window) : nlohmann::json();
  a.event = {{"class", "CALIBRATION_ACTIVE"},
             {"t", t_s},
             {"device", d.name},
             {"model", thermal_name},
             {"version", active_version_},
             {"poses", thermal.poses},
             {"moves", 0},
             {"range_c", {thermal.t_min_c, thermal.t_max_c}}};
  a.apply = [this, version = active_version_, e = thermal, window = estimate.bias_window] {
    if (version > applied_version_) ApplyThermal(version, e, window);
  };
  return a;
}

nlohmann::json ThermalModelPipeline::StatusJson() const {
  return {
      {"poses", thermal.poses},
      {"gate", ToJson(gate)},
      {"fit_check", ToString(thermal.fit.verdict)},
      {"range_c", thermal.ok ? nlohmann::json{thermal.t_min_c, thermal.t_max_c} : nlohmann::json()},
      {"distinct_temperatures", thermal.distinct_temperatures},
      {"applied_range_c", applied_version_ > 0 && applied.ok
                              ? nlohmann::json{applied.t_min_c, applied.t_max_c}
                              : nlohmann::json()},
      {"outside_range",
       {{"below", samples_below},
        {"above", samples_above},
        {"no_temperature", samples_without_temperature},
        {"last_c",
         samples_below + samples_above > 0 ? nlohmann::json(last_outside_c) : nlohmann::json()}}},
      {"active_version", active_version_},
      {"applied_version", applied_version_}};
}

nlohmann::json ThermalModelPipeline::ResultJson() const {
  return {{"ok", thermal.ok},
          {"base_model", model->name()},
          {"poses", thermal.poses},
          {"rank", thermal.rank},
          {"bias_window",
           estimate.bias_window ? protocol::ToJson(*estimate.bias_window) : nlohmann::json()},
          {"temperature", protocol::ToJson(thermal)},
          {"gate", ToJson(gate)},
          {"active_version", active_version_}};
}

}  // namespace turncal::daemon
