#pragma once
// A pose model over temperature (issue 36): "accel13@T" in a device's models is accel13 with every
// parameter a polynomial in the sensor's temperature (core/estimation/thermal_calibrator.h),
// refitted after every pose from all the device's poses at every temperature, gated over the whole
// calibrated range (core/analysis/thermal_gate.h), stored as calibrations/DEVICE.accel13@T.json
// (protocol/thermal_json.h), and applied to each live sample at that sample's temperature.
//
// It is a ModelPipeline whose own calibrator (isothermal: every parameter at order 0, its drift
// not identified) only serves the next-pose planner; its estimate, gate, document and correction
// are the thermal fit's. A sample outside [T_min, T_max] is corrected with the parameters at the
// nearer end and flagged ("above_range", "below_range"); one without a temperature with the
// parameters at t0, flagged "no_temperature". A pose without a temperature is refused with the
// reason (nothing is lost: the journal keeps it). The fit is repeated after every pose up to 30,
// then whenever the poses have grown by a tenth (its cost grows with the cube of the poses), and
// once more when the input ends (a replay).

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/analysis/thermal_gate.h"
#include "core/estimation/thermal_calibrator.h"
#include "daemon/station/model_pipeline.h"

namespace turncal::daemon {

// "accel13@T" -> true and "accel13"; false for any other name.
bool IsThermalModelName(const std::string& name, std::string* base = nullptr);

// The pose model `name` (a ThermalModelPipeline for "MODEL@T").
std::unique_ptr<ModelPipeline> MakePoseModel(const std::string& name, const StationOptions& options,
                                             const SensorClass& sensor);

struct ThermalModelPipeline : ModelPipeline {
  ThermalModelPipeline(ModelPipeline base, const StationOptions& options);

  std::string thermal_name;  // "accel13@T"
  ThermalOptions fit_options;
  ThermalGateOptions gate_options;
  double max_pose_span_c = 5.0;      // a pose's temperature may move this much in its window
  CalibratorOptions fit_calibrator;  // the thermal fit's weighting and drift
  std::vector<PoseRecord> records;   // every pose fitted (under calibrator_mutex)
  ThermalEstimate thermal;           // the latest
  ThermalEstimate active_thermal;
  // Applied to live samples (ok: one is), with the bias window of its latest pose.
  ThermalEstimate applied;
  // Live samples corrected outside the range or without a temperature, since the start.
  mutable std::int64_t samples_below = 0, samples_above = 0, samples_without_temperature = 0;
  mutable double last_outside_c = 0.0;

  // The polynomials at `temp_c` (clamped into the applied range): theta and its covariance.
  void ApplyThermal(int version, const ThermalEstimate& e, const std::optional<TimeWindow>& window);

  // ModelPipeline:
  void AddAndSolve(const PoseRecord& record, const GateOptions& gate, ModelUpdate* job) override;
  bool HasPending() const override;
  void SolvePending(const GateOptions& gate, ModelUpdate* job) override;
  void TakeUpdate(const ModelUpdate& job) override;
  nlohmann::json EstimateEventJson(const GateOptions& gate) const override;
  void ApplyCurrentEstimate() override;
  nlohmann::json PrecisionJson(const GateOptions& gate) const override;

  // Calibration:
  const std::string& name() const override { return thermal_name; }
  bool Correct(const Sample& sample, double t_s, Eigen::Vector3d* value,
               std::optional<Eigen::Vector3d>* sigma, const char** frame) const override;
  const char* TemperatureFlag(const Sample& sample) const override;
  bool ApplyStored(const nlohmann::json& stored, std::string* error) override;
  bool HasEstimate(std::string* error) const override;
  Activation Activate(const DevicePipeline& device, const ActivationContext& context,
                      double t_s) override;
  nlohmann::json StatusJson() const override;
  nlohmann::json ResultJson() const override;
  // A device stores no polynomials in temperature (MIP and Xbus store one set of coefficients).
  const MeasurementModel* writable_model() const override { return nullptr; }

 private:
  // The thermal fit of every record (under the calibrator's lock).
  void Fit(const GateOptions& gate, ModelUpdate* job);
  std::size_t fitted_ = 0;       // records in the latest fit
  std::size_t next_fit_at_ = 0;  // the record count that fits again
  // Records added since the latest fit (read on the loop without the calibrator's lock, which a
  // fit holds for seconds).
  std::atomic<bool> pending_{false};
  // Where a sample's correction is evaluated, and its flag (nullptr: inside the range).
  double EvaluationTemperature(const Sample& sample, const char** flag) const;
};

}  // namespace turncal::daemon
