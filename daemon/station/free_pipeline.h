#pragma once
// One device's calibration without known poses in the station (issue 22: [station] pose_source =
// "free", docs/FREE.md "In the daemon"). The device's sequencer runs in free mode and finds the
// static intervals itself; after each one every free model of the device is fitted again to all
// of them on the solve worker (FreeUpdate), with the advice on the orientation to add; the
// station gates each, and a model whose gate passes becomes active: versioned, written to the
// state directory (protocol/free_json.h) and applied to live samples (FreeModelState::Correct).

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/analysis/free_advice.h"
#include "core/analysis/publish_gate.h"
#include "core/estimation/free_calibrator.h"
#include "core/estimation/sensor_class.h"

namespace turncal::daemon {

struct StationOptions;

// The free models' context from the station's options: gravity's magnitude and the latitude from
// [reference], the field's magnitude from [reference] unless [free] field = "unknown" (then the
// soft iron is relative), the field's dip for the advice, and each triad's bias drift from the
// sensor class when the station models drift ([station] drift_model), else an independent offset
// per interval of the class's bias instability.
FreeContext FreeContextFor(const StationOptions& options, const SensorClass& sensor);
// The free calibrator's gate: [free] min_coverage_percent, and the station's [gate] (every sensor
// parameter's sigma within its tolerance, min_dof, min_p_value).
FreeCalibratorOptions FreeOptionsFor(const StationOptions& options, const GateOptions& gate);
// The frame a free model's corrected output is in: "accelerometer" (the accelerometer triad's own,
// as accel9 fixes it; gyro9's and accmag's outputs are turned into it) or "magnetometer" (the
// magnetometer triad's own: magellipsoid's soft iron is symmetric).
const char* FreeOutputFrame(const std::string& model);
// The moves a free estimate used (gyro9's direction terms, one per move between two intervals).
int MovesUsed(const FreeEstimate& estimate);

// What one interval's update computes (on the solve worker when there is one).
struct FreeUpdate {
  std::size_t intervals = 0;             // the device's intervals it saw
  std::vector<std::string> models;       // the models fitted (configured, or what the data carry)
  std::string error;                     // the models could not be made
  std::vector<FreeModelResult> results;  // upstreams first (CalibrateFreeModels)
  std::vector<std::optional<OrientationAdvice>> advice;  // per result

  // Fits `configured` (empty: DefaultFreeModels of the intervals) to `intervals`.
  void Run(const std::vector<std::string>& configured, const std::vector<FreeInterval>& intervals,
           const FreeContext& context, const FreeCalibratorOptions& options);
};

// One free model of a device.
struct FreeModelState {
  std::string requested;  // as configured or chosen ("magellipsoid")
  SensorKind sensor = SensorKind::kAccelerometer;
  FreeModelResult result;                   // the latest fit; result.model is what was fitted
  std::optional<FreeModelResult> upstream;  // the estimate it built on (gyro9's accel9)
  std::optional<OrientationAdvice> advice;
  std::size_t estimate_intervals = 0;  // the device's intervals `result` saw
  int active_version = 0;              // 0: no active calibration

  // The calibration live samples are corrected with (version 0: none): the active one, or the
  // one stored in the state directory when the station started.
  int applied_version = 0;
  std::shared_ptr<const FreeModel> applied_model, applied_upstream_model;
  Eigen::VectorXd applied_theta, applied_upstream_theta;
  Eigen::MatrixXd applied_covariance;             // empty when unknown
  std::optional<TimeWindow> applied_bias_window;  // host clock
  BiasDrift applied_drift;

  int triad() const;  // kTriadAcc, kTriadGyr or kTriadMag
  void Apply(int version, const std::string& model, const Eigen::VectorXd& theta,
             const Eigen::MatrixXd& covariance, const std::string& upstream_model,
             const Eigen::VectorXd& upstream_theta, const std::optional<TimeWindow>& bias_window,
             const FreeContext& context);
  // Applies a calibration document read from the state directory (protocol/free_json.h).
  bool ApplyStored(const nlohmann::json& stored, std::string* error);
  // One raw sample of the model's triad corrected (gyro9g's g-sensitivity from the raw
  // accelerometer `acc_raw` through the upstream's correction; without it, none is taken off),
  // and with `sigma` its 1 sigma from the covariance plus the bias's wander since the calibration
  // at host time t_s (J Sigma J^T, J by central differences; the noise not included).
  Eigen::Vector3d Correct(const Eigen::Vector3d& raw, const Eigen::Vector3d* acc_raw, double t_s,
                          std::optional<Eigen::Vector3d>* sigma) const;
  // Every gated parameter's sigma against its tolerance (ESTIMATE's precision).
  nlohmann::json PrecisionJson(const GateOptions& gate) const;
  nlohmann::json ResultJson() const;
  nlohmann::json StatusJson() const;
};

struct FreeDevice {
  std::vector<std::string> configured;  // empty: what the data carry
  FreeContext context;
  FreeCalibratorOptions options;
  // Stable addresses: queued completions hold them while models are added.
  std::vector<std::unique_ptr<FreeModelState>> models;
  // The latest update's results (upstreams included) and advice, for the report.
  std::vector<FreeModelResult> results;
  std::vector<std::optional<OrientationAdvice>> advice;
  std::size_t results_intervals = 0;
  // Still segments the sequencer skipped (too short, not still enough), the latest reasons kept.
  std::int64_t skipped = 0;
  std::vector<std::string> skip_reasons;
  static constexpr std::size_t kMaxSkipReasons = 50;
  // A resumed journal's intervals are fitted once, at the end of the resume.
  bool refit_due = false;

  FreeModelState* Find(const std::string& requested);
  FreeModelState& Get(const std::string& requested);  // created when new
  // Takes an update: each model's result, upstream and advice. Returns the models it updated.
  std::vector<FreeModelState*> Take(const FreeUpdate& update);
  void NoteSkipped(const std::string& reason);
  // {"pose_source":"free","intervals","skipped","skip_reasons","models":{REQUESTED: ...}}
  nlohmann::json ResultJson(std::size_t intervals) const;
  nlohmann::json StatusJson(std::size_t intervals) const;
  // NEXT_POSE for a free device: the orientation to add per model, and the gates.
  nlohmann::json NextPoseJson(const std::string& device) const;
};

}  // namespace turncal::daemon
