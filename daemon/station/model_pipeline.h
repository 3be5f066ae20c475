#pragma once
// One model of one device in the station: its calibrator and latest estimate, the gate's verdict,
// the active calibration's version, and the calibration applied to live samples (with the
// correction's sigma growing with the time since). The station (daemon/station/station.h) wires it
// to the device's poses, the solve worker, persistence and events.

#include <functional>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "core/analysis/observability.h"
#include "core/analysis/publish_gate.h"
#include "core/estimation/calibrator.h"
#include "core/estimation/sensor_class.h"
#include "core/estimation/thermal_calibrator.h"
#include "core/modeling/measurement_model.h"
#include "core/sequencing/sample.h"
#include "daemon/station/calibration.h"

namespace turncal::daemon {

struct StationOptions;

// The 1 sigma per axis of a correction `corrected(theta)` from theta's `covariance`: J C J^T, J by
// central differences (steps of 1e-6 of each parameter's scale).
Eigen::Vector3d PropagatedSigma(
    const std::function<Eigen::Vector3d(const Eigen::VectorXd&)>& corrected,
    const Eigen::VectorXd& theta, const Eigen::MatrixXd& covariance);

// 1 sigma per axis of model.Correct(theta, raw) from cov(theta) (PropagatedSigma); nullopt
// without a usable covariance. `bias_drift_var`, per axis, is added to the bias parameters'
// variance: how far the bias may have wandered since the calibration. With `f_q` a
// g-sensitivity (gyro21's B_g) comes off the raw rate first, so its covariance counts too.
std::optional<Eigen::Vector3d> CorrectionSigma(
    const MeasurementModel& model, const Eigen::VectorXd& theta, Eigen::MatrixXd covariance,
    const Eigen::Vector3d& raw, const Eigen::Vector3d& bias_drift_var, const Eigen::Vector3d* f_q);

// The raw rate with the g-sensitivity's share removed: raw - B_g f_q, B_g read row-major from
// theta at model.index_of("Bg_xx"). Unchanged when the model has no B_g or `f_q` is null.
Eigen::Vector3d WithoutGSensitivity(const MeasurementModel& model, const Eigen::VectorXd& theta,
                                    const Eigen::Vector3d& raw, const Eigen::Vector3d* f_q);

// The specific force in the sensor's frame (mounting^T acc) that a gyroscope's g-sensitivity
// multiplies; nullopt unless the model is a gyroscope's and the sample carries acceleration.
std::optional<Eigen::Vector3d> GyroSpecificForce(const MeasurementModel& model, int triad,
                                                 const Sample& sample);

// The `bias_window` of a stored calibration document, when it has a valid one.
std::optional<TimeWindow> StoredBiasWindow(const nlohmann::json& stored);

// What one pose's update computes (on the solve worker when there is one).
struct ModelUpdate {
  std::size_t device_poses = 0;  // the device's poses when the update was queued, this one included
  bool added = false;
  std::string error;
  Estimate estimate;
  int rank = 0;
  GateResult gate;
  // A gyroscope's moves the calibrator could not use, and why the latest was refused.
  int moves_refused = 0;
  std::string last_move_refusal;
  // False when the pose was added but the estimate not recomputed (a calibration over
  // temperature refits as its poses grow by a tenth): nothing to announce or activate.
  bool solved = true;
  // A calibration over temperature's (daemon/station/thermal_pipeline.h): its fit, and `gate` the
  // gate over its range.
  ThermalEstimate thermal;
};

// One pose model of a device: a Calibration (daemon/station/calibration.h). A calibration over
// temperature (ThermalModelPipeline) is one too, with its own solve, document and correction.
struct ModelPipeline : Calibration {
  std::unique_ptr<MeasurementModel> model;
  std::unique_ptr<Calibrator> calibrator;
  Estimate estimate;
  // How many of the device's poses (poses_used, records_used) `estimate` saw: later poses may be
  // captured while its solve runs, and a calibration carries only its own evidence.
  std::size_t estimate_poses = 0;
  GateResult gate;
  int rank = 0;
  int moves_refused = 0;  // as of the latest update (ModelUpdate)
  std::string last_move_refusal;
  int active_version_ = 0;  // 0: no active calibration
  Estimate active;
  // The calibration live samples are corrected with: the active one, or the one stored in the
  // state directory when the station started (version 0 / empty: none).
  int applied_version_ = 0;
  Eigen::VectorXd applied_theta;
  Eigen::MatrixXd applied_covariance;  // empty when unknown
  // With a drift model: when the applied bias held, and how the bias wanders since (the
  // corrected output's sigma grows with the time since).
  std::optional<TimeWindow> applied_bias_window;
  BiasDrift applied_drift;
  // The correction as y = A raw + c, when the model's correction is affine in the raw sample (all
  // four models are: checked numerically when the calibration is applied). Live samples are
  // corrected with it, without the model's per-sample matrix solves.
  bool applied_affine = false;
  Eigen::Matrix3d applied_A = Eigen::Matrix3d::Identity();
  Eigen::Vector3d applied_c = Eigen::Vector3d::Zero();
  // The calibrator is solved on the service's worker thread; this guards it.
  std::unique_ptr<std::mutex> calibrator_mutex = std::make_unique<std::mutex>();

  // The model `name` with the calibrator the station's options and sensor class call for.
  static ModelPipeline Make(const std::string& name, const StationOptions& options,
                            const SensorClass& sensor);

  // The record's statistics of the model's triad (nullptr when it has none).
  const TriadStats* TriadOf(const PoseRecord& record) const;
  // Applies a calibration to live samples.
  void Apply(int version, const Eigen::VectorXd& theta, const Eigen::MatrixXd& covariance,
             const std::optional<TimeWindow>& bias_window, const BiasDrift& drift);
  // Adds the pose and solves, analyses and gates (under the calibrator's lock).
  virtual void AddAndSolve(const PoseRecord& record, const GateOptions& gate, ModelUpdate* job);
  // Poses added but not yet solved for (SolvePending solves them).
  virtual bool HasPending() const { return false; }
  virtual void SolvePending(const GateOptions& gate_options, ModelUpdate* job) {
    (void)gate_options, (void)job;
  }
  // The update back on the loop: the estimate, its gate and rank become the current ones.
  virtual void TakeUpdate(const ModelUpdate& job);
  // The ESTIMATE event's "poses", "moves", "summary" and "precision".
  virtual nlohmann::json EstimateEventJson(const GateOptions& gate) const;
  // While resuming: the current estimate is applied under the stored version (its gate passed).
  virtual void ApplyCurrentEstimate();
  // The applied calibration's correction of one raw triad sample, and with `sigma` its 1 sigma
  // (the covariance plus the bias's wander since the calibration, at host time t_s).
  // A gyroscope model's g-sensitivity needs the specific force in the table frame, `f_q` (the
  // station passes the raw accelerometer turned by the nominal mounting; gyro12 ignores it).
  Eigen::Vector3d Correct(const Eigen::Vector3d& raw, double t_s,
                          std::optional<Eigen::Vector3d>* sigma,
                          const Eigen::Vector3d* f_q = nullptr) const;

  // Per axis, the variance the applied bias may have wandered by since its window, at host time
  // t_s (zero without a drift model).
  Eigen::Vector3d DriftVarianceSince(double t_s) const;

  // Every gated parameter's sigma against its tolerance (ESTIMATE's precision).
  virtual nlohmann::json PrecisionJson(const GateOptions& gate) const;

  // Calibration:
  const std::string& name() const override { return model->name(); }
  int triad() const override;
  int active_version() const override { return active_version_; }
  int applied_version() const override { return applied_version_; }
  // A gyroscope's g-sensitivity sees the specific force in the table frame: the sample's raw
  // accelerometer turned back by the nominal mounting (its own errors, ~1e-3, are far below
  // what B_g needs).
  bool Correct(const Sample& sample, double t_s, Eigen::Vector3d* value,
               std::optional<Eigen::Vector3d>* sigma, const char** frame) const override;
  // The version is taken even when the values are unreadable: versions go on from it.
  bool ApplyStored(const nlohmann::json& stored, std::string* error) override;
  bool HasEstimate(std::string* error) const override;
  bool GatePassed() const override { return gate.pass; }
  std::vector<std::string> GateReasons() const override { return gate.reasons; }
  Activation Activate(const DevicePipeline& device, const ActivationContext& context,
                      double t_s) override;
  nlohmann::json StatusJson() const override;
  nlohmann::json ResultJson() const override;
  const MeasurementModel* writable_model() const override { return model.get(); }
};

}  // namespace turncal::daemon
