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
#include "core/analysis/live_coverage.h"
#include "core/analysis/publish_gate.h"
#include "core/estimation/free_calibrator.h"
#include "core/estimation/free_motion.h"
#include "core/estimation/sensor_class.h"
#include "daemon/station/calibration.h"

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
  // What was fitted: the still intervals, then the magnetometer's points in motion (issue 37).
  std::shared_ptr<const std::vector<FreeInterval>> data;
  std::optional<MotionPoints> motion;  // when the magnetometer's values in motion were looked at

  // Fits `configured` (empty: DefaultFreeModels of the data) to `intervals` and, with `motion`,
  // the magnetometer's values in motion outside them (MotionCollector::Select).
  void Run(const std::vector<std::string>& configured, const std::vector<FreeInterval>& intervals,
           const MotionCollector* motion, const MotionOptions& motion_options,
           const FreeContext& context, const FreeCalibratorOptions& options);
};

// The magnetometer's values in motion of a free-mode device's stream ([free] motion): kept, put in
// the journal at least every kFlushS, and fitted with the still intervals -- when their count has
// doubled since the last fit, at least every kRefitS while new ones arrive, and at the input's end.
struct FreeMotionState {
  static constexpr double kFlushS = 1.0;
  static constexpr double kRefitS = 10.0;
  static constexpr std::int64_t kFirstFit = 50;  // values before the first fit in motion
  // COVERAGE events while values arrive, from kFirstFit values (fewer have no centre).
  static constexpr double kCoverageEveryS = 0.5;
  bool enabled = false;
  MotionCollector collector;
  LiveCoverage coverage;  // the collector's values' directions, for the live guidance
  double coverage_published_s = -1e300;
  std::vector<MotionValue> unjournaled;
  std::int64_t kept = 0,
               kept_at_fit = 0;  // values kept in all (thinned or not), and at the last fit
  double flushed_s = -1e300, fitted_s = -1e300;  // host times
  std::optional<MotionPoints> last;              // the last fit's selection
  nlohmann::json Json() const;                   // status/RESULT "motion"
};

class FreeCalibrations;

// One free model of a device: a Calibration (daemon/station/calibration.h).
struct FreeModelState : Calibration {
  const FreeCalibrations* owner = nullptr;  // the device's set: its context and gate
  std::string requested;                    // as configured or chosen ("magellipsoid")
  SensorKind sensor = SensorKind::kAccelerometer;
  FreeModelResult result;                   // the latest fit; result.model is what was fitted
  std::optional<FreeModelResult> upstream;  // the estimate it built on (gyro9's accel9)
  std::optional<OrientationAdvice> advice;
  std::size_t estimate_intervals = 0;  // the device's intervals `result` saw
  std::shared_ptr<const std::vector<FreeInterval>> estimate_data;  // and all it fitted
  int active_version_ = 0;                                         // 0: no active calibration

  // The calibration live samples are corrected with (version 0: none): the active one, or the
  // one stored in the state directory when the station started.
  int applied_version_ = 0;
  std::shared_ptr<const FreeModel> applied_model, applied_upstream_model;
  Eigen::VectorXd applied_theta, applied_upstream_theta;
  Eigen::MatrixXd applied_covariance;             // empty when unknown
  std::optional<TimeWindow> applied_bias_window;  // host clock
  BiasDrift applied_drift;

  void Apply(int version, const std::string& model, const Eigen::VectorXd& theta,
             const Eigen::MatrixXd& covariance, const std::string& upstream_model,
             const Eigen::VectorXd& upstream_theta, const std::optional<TimeWindow>& bias_window,
             const FreeContext& context);
  // The latest fit applied again as the active version (a resumed session's).
  void ApplyResult(const FreeContext& context);
  // One raw sample of the model's triad corrected (gyro9g's g-sensitivity from the raw
  // accelerometer `acc_raw` through the upstream's correction; without it, none is taken off),
  // and with `sigma` its 1 sigma from the covariance plus the bias's wander since the calibration
  // at host time t_s (J Sigma J^T, J by central differences; the noise not included).
  Eigen::Vector3d Correct(const Eigen::Vector3d& raw, const Eigen::Vector3d* acc_raw, double t_s,
                          std::optional<Eigen::Vector3d>* sigma) const;
  // Every gated parameter's sigma against its tolerance (ESTIMATE's precision).
  nlohmann::json PrecisionJson(const GateOptions& gate) const;

  // Calibration:
  const std::string& name() const override { return requested; }
  int triad() const override;  // kTriadAcc, kTriadGyr or kTriadMag
  int active_version() const override { return active_version_; }
  int applied_version() const override { return applied_version_; }
  bool Correct(const Sample& sample, double t_s, Eigen::Vector3d* value,
               std::optional<Eigen::Vector3d>* sigma, const char** frame) const override;
  // A document written by a free model's activation (protocol/free_json.h).
  bool ApplyStored(const nlohmann::json& stored, std::string* error) override;
  bool HasEstimate(std::string* error) const override;
  bool GatePassed() const override { return result.estimate.gate_passed; }
  std::vector<std::string> GateReasons() const override { return result.estimate.gate_reasons; }
  Activation Activate(const DevicePipeline& device, const ActivationContext& context,
                      double t_s) override;
  nlohmann::json ResultJson() const override;
  nlohmann::json StatusJson() const override;
};

// A device's free models (the free pose source): a CalibrationSet (daemon/station/calibration.h)
// whose models are fitted together after every static interval (daemon/station/
// free_calibrations.cc).
class FreeCalibrations : public CalibrationSet {
 public:
  // `configured` empty: the models the data carry (DefaultFreeModels).
  FreeCalibrations(std::vector<std::string> configured, const StationOptions& options,
                   const SensorClass& sensor, const GateOptions& gate);

  const FreeContext& context() const { return context_; }
  const FreeCalibratorOptions& options() const { return options_; }

  // CalibrationSet:
  std::size_t size() const override { return models_.size(); }
  Calibration& at(std::size_t i) override { return *models_[i]; }
  const Calibration& at(std::size_t i) const override { return *models_[i]; }
  std::vector<std::string> StoredNames() const override;  // with models from the data, any
  Calibration& Restore(const std::string& name) override { return Get(name); }
  bool NeedsMoves() const override;
  void Start(Sequencer& sequencer) override;  // free mode: it announces the first interval
  void OnRecord(DevicePipeline& d, const PoseRecord& record, double t_s, bool resuming,
                CalibrationHost& host) override;
  void OnResumed(DevicePipeline& d, CalibrationHost& host) override;
  // The magnetometer's values in motion ([free] motion): kept, journaled, refitted.
  void OnSample(DevicePipeline& d, const Sample& sample, CalibrationHost& host) override;
  void OnMotionValues(DevicePipeline& d, const std::vector<MotionValue>& values) override;
  void OnFinish(DevicePipeline& d, CalibrationHost& host) override;
  void OnSequencerEvent(const SequencerEvent& event) override;  // counts skipped segments
  // The orientation to add per model, and the gates.
  nlohmann::json NextPose(const DevicePipeline& d, const StationOptions& options) const override;
  const char* pose_source() const override { return "free"; }
  // {"pose_source":"free","intervals","skipped","last_skip"} and {"pose_source":"free",
  // "intervals","skipped","skip_reasons","context"}.
  nlohmann::json SourceStatusJson(const DevicePipeline& d) const override;
  nlohmann::json SourceResultJson(const DevicePipeline& d) const override;

 private:
  FreeModelState* FindModel(const std::string& requested);
  FreeModelState& Get(const std::string& requested);  // created when new
  // Fits every model again to all of the device's intervals, on the host's worker.
  void QueueFit(DevicePipeline& d, double t_s, bool resuming, CalibrationHost& host);
  // Takes an update: each model's result, upstream and advice. Returns the models it updated.
  std::vector<FreeModelState*> Take(const FreeUpdate& update);
  void ApplyUpdate(DevicePipeline& d, const FreeUpdate& job, double t_s, bool resuming,
                   CalibrationHost& host);
  void PublishEstimate(const DevicePipeline& d, const FreeModelState& m, double t_s,
                       CalibrationHost& host) const;
  // The magnetometer's coverage so far (COVERAGE, docs/protocol.md): the bins, the largest
  // region without a value and what to do about it.
  void PublishCoverage(const DevicePipeline& d, double t_s, CalibrationHost& host);
  // The latest fit of a magnetometer model corrects the values' directions from now on.
  void TakeCoverageCorrection(const FreeUpdate& update);

  std::vector<std::string> configured_;  // empty: what the data carry
  FreeContext context_;
  FreeCalibratorOptions options_;
  // Stable addresses: queued completions hold them while models are added.
  std::vector<std::unique_ptr<FreeModelState>> models_;
  // Still segments the sequencer skipped (too short, not still enough), the latest reasons kept.
  std::int64_t skipped_ = 0;
  std::vector<std::string> skip_reasons_;
  static constexpr std::size_t kMaxSkipReasons = 50;
  // A resumed journal's intervals are fitted once, at the end of the resume.
  bool refit_due_ = false;
  bool needs_moves_ = false;
  FreeMotionState motion_;
  MotionOptions motion_options_;
  Eigen::Vector3d class_mag_sigma_ = Eigen::Vector3d::Zero();  // per sample, the class's
  std::string class_noise_source_;
  bool fit_in_flight_ = false;
  struct PendingFit {
    double t_s;
    bool resuming;
  };
  std::optional<PendingFit> pending_fit_;  // asked for while one was in flight
  void FlushMotion(DevicePipeline& d, CalibrationHost& host);
};

}  // namespace turncal::daemon
