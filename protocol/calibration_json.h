#pragma once
// The active calibration document (daemon/state/persistence.h: calibrations/DEVICE.MODEL.json,
// schema 1) as the report reads it, and the keys the station writes so that a calibration can be
// re-evaluated offline without the daemon's configuration:
//
//   "context":    {"g_ned":[3], "B_ned":[3], "mounting":[[3]x3], "accel_output_frame":"case"}
//   "calibrator": {"sensor_class", "noise_density", "pose_offset_sigma", "loss", "loss_scale",
//                  "drift": {"gauss_markov_sigma":[3], "gauss_markov_tau_s", "random_walk":[3],
//                            "warmup_sigma":[3], "warmup_tau_s"[, "warmup_origin_s"]}}
//   "bias_window": {"t0_s", "t1_s"}: when the bias parameters hold (the latest pose's window, on
//                  the station's host clock), with a drift model
//   "tolerances": {NAME: 1-sigma tolerance} for every gated parameter, in the parameter's units
//   "provenance": {"poses":[...], "records":[pose record, as ToJson(PoseRecord)], ...}
//
// Documents written before these keys existed still parse: the defaults are used (and said so).

#include <Eigen/Core>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/analysis/publish_gate.h"
#include "core/estimation/calibrator.h"
#include "core/estimation/pose_record.h"
#include "core/modeling/measurement_model.h"

namespace turncal::protocol {

nlohmann::json ToJson(const ModelContext& context);
// False with a message when a key is malformed or the context is invalid; absent keys keep *out's.
bool ParseModelContext(const nlohmann::json& j, ModelContext* out, std::string* error);

// The calibrator's noise model and loss, with the sensor class it came from.
nlohmann::json CalibratorJson(const CalibratorOptions& options, const std::string& sensor_class);

// The two-sided fit check: {"verdict":"ok|chi2_too_large|chi2_too_small","chi2_per_dof",
// "p_upper","p_lower","axis_ratio":[3],"lag1_correlation","cause","message"}.
nlohmann::json ToJson(const FitCheck& fit, SensorKind sensor);

// The calibrator's drift model, and the time window of a calibration's bias.
nlohmann::json ToJson(const BiasDrift& drift);
bool ParseBiasDrift(const nlohmann::json& j, BiasDrift* out);
nlohmann::json ToJson(const TimeWindow& window);
// The drift's strength identified from the poses: {"identified","scale","log_sigma","data_scale",
// "data_log_sigma","prior_log_sigma","rejects_prior","use_scale"} (null for an infinite sigma).
nlohmann::json ToJson(const DriftScale& scale);
bool ParseTimeWindow(const nlohmann::json& j, TimeWindow* out);

// Every gated parameter's tolerance (GatedParameters, ToleranceFor).
nlohmann::json TolerancesJson(const MeasurementModel& model, const GateOptions& gate);

// An estimate's parameters, {NAME:{"value","sigma"}} in the model's order (sigma null when
// undetermined; empty while the solve is refused), and the drift's identified strength with the
// scale the solve used ("used": 1 while the poses do not reject the prior).
nlohmann::json ParamsJson(const Estimate& e);
// A covariance matrix as rows of numbers (null where not finite).
nlohmann::json CovarianceJson(const Eigen::MatrixXd& covariance);
nlohmann::json DriftScaleJson(const Estimate& e);

// What a pose model's activation writes (daemon/station/model_pipeline.h): the document the
// parser below reads. `poses` and `records` are the device's, the first `count` of them the
// estimate saw; the document keeps those that hold the model's triad, each record with that triad
// only (and a gyroscope's moves), so that it can be re-evaluated without the journal.
struct PoseCalibrationInput {
  std::string device;
  int version = 0;
  const MeasurementModel* model = nullptr;  // required
  const Estimate* estimate = nullptr;       // required
  int rank = 0;
  GateResult gate;
  GateOptions gate_options;  // the tolerances gated against
  CalibratorOptions calibrator;
  std::string sensor_class;
  ModelContext context;
  const std::vector<TablePose>* poses = nullptr;     // required
  const std::vector<PoseRecord>* records = nullptr;  // required
  std::size_t count = 0;
  nlohmann::json identity;  // the device dialogue's (null in replays)
};
// The document (schema 1), with "software" set; the caller adds "time".
nlohmann::json PoseCalibrationJson(const PoseCalibrationInput& input);

// The values a station applies to live samples (and a device write stores) from a document:
// the parameters in `model`'s order and the covariance (empty when the document has none, or it
// is not the model's size or holds a non-number). False when a parameter is missing.
bool ReadCalibrationValues(const MeasurementModel& model, const nlohmann::json& calibration,
                           Eigen::VectorXd* theta, Eigen::MatrixXd* covariance);

// A document's gate tolerances: its "tolerances" when it records them (*recorded), else the
// class's (industrial's when `sensor_class` is empty) for the model's gated parameters. False with
// a reason when "tolerances" is malformed or names no parameter of the model.
bool ReadTolerances(const nlohmann::json& j, const MeasurementModel& model,
                    const std::string& sensor_class, std::map<std::string, double>* tolerances,
                    bool* recorded, std::string* why);

// One calibration document, parsed and checked against its model.
struct CalibrationDocument {
  std::string device;
  std::string model;
  int version = 0;
  std::string software;
  std::string time;
  std::unique_ptr<MeasurementModel> measurement_model;  // with `context`
  ModelContext context;
  bool context_recorded = false;
  Eigen::VectorXd theta;       // in the model's order
  Eigen::VectorXd sigma;       // NaN where the document has null
  Eigen::MatrixXd covariance;  // empty when absent; NaN where null
  std::string gauge;
  int rank = 0;
  double chi2 = 0.0;
  int dof = 0;
  double p_value = 1.0;
  std::string fit_verdict;  // FitCheck's, "" when the document predates it
  std::string fit_message;
  // calibrator.drift_scale: the drift's strength the poses alone give (data_scale, with the 1
  // sigma of its log) and the scale the solve used (absent: not identified).
  std::optional<double> drift_scale, drift_scale_log_sigma, drift_scale_used;
  GateResult gate;
  nlohmann::json override_who;  // null unless published by operator override
  nlohmann::json identity;      // provenance.device_identity (null in replays)
  std::vector<TablePose> poses;
  std::vector<PoseRecord> records;           // provenance.records; empty when not recorded
  CalibratorOptions calibrator;              // recorded, else the industrial class's for the model
  std::string sensor_class;                  // "" when not recorded
  std::map<std::string, double> tolerances;  // recorded, else the industrial class's
  bool tolerances_recorded = false;
};

// False with a message naming the key when the document is not a calibration of a known model
// with a finite value for each of its parameters, or a present key has the wrong shape.
bool ParseCalibrationDocument(const nlohmann::json& j, CalibrationDocument* out,
                              std::string* error);

}  // namespace turncal::protocol
