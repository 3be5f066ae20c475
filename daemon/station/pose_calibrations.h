#pragma once
// A device's pose models (accel13, mag13, gyro12, gyro21, ...: core/models/) as the station's
// calibration set (daemon/station/calibration.h): each model its own calibrator
// (daemon/station/model_pipeline.h), solved on the worker after every pose that holds its triad,
// gated, and activated when its gate passes; the next pose is D-optimal over all of them.

#include <memory>
#include <string>
#include <vector>

#include "core/estimation/sensor_class.h"
#include "core/planning/pose_planner.h"
#include "daemon/station/calibration.h"
#include "daemon/station/model_pipeline.h"

namespace turncal::daemon {

class PoseCalibrations : public CalibrationSet {
 public:
  PoseCalibrations(const std::vector<std::string>& models, const StationOptions& options,
                   const SensorClass& sensor);

  // What the next-pose planner needs of each model: its poses, weights and the device's noise.
  std::vector<PlanningTarget> PlanningTargets(const DevicePipeline& d,
                                              double dwell_s) const override;
  // The planner's options for a device of the station: the table's motion, objective, dwell,
  // rates, and where the table is (the device's latest announced pose).
  static PlannerOptions PlannerFor(const DevicePipeline& d, const StationOptions& options);

  // CalibrationSet:
  std::size_t size() const override { return models_.size(); }
  Calibration& at(std::size_t i) override { return *models_[i]; }
  const Calibration& at(std::size_t i) const override { return *models_[i]; }
  std::vector<std::string> StoredNames() const override;
  Calibration& Restore(const std::string& name) override { return *Find(name); }
  bool NeedsMoves() const override;
  void OnRecord(DevicePipeline& d, const PoseRecord& record, double t_s, bool resuming,
                CalibrationHost& host) override;
  // Solves what was deferred (a calibration over temperature's latest poses).
  void OnFinish(DevicePipeline& d, CalibrationHost& host) override;
  void OnResumed(DevicePipeline& d, CalibrationHost& host) override;
  // Once per record count: a calibration over temperature's deferred fit.
  void OnIdle(DevicePipeline& d, CalibrationHost& host) override;
  // D-optimal over every model of the device (core/planning/pose_planner.h).
  nlohmann::json NextPose(const DevicePipeline& d, const StationOptions& options) const override;
  const char* pose_source() const override { return "announced"; }
  nlohmann::json SourceStatusJson(const DevicePipeline&) const override { return nullptr; }
  nlohmann::json SourceResultJson(const DevicePipeline&) const override { return nullptr; }

 private:
  // One model's update back on the loop: ESTIMATE, the drift it identified, and activation.
  void Apply(DevicePipeline& d, ModelPipeline& m, double t_s, const ModelUpdate& job, bool resuming,
             CalibrationHost& host);

  // Made once: queued updates hold their addresses. A name with "@T" is a calibration over
  // temperature (daemon/station/thermal_pipeline.h).
  std::vector<std::unique_ptr<ModelPipeline>> models_;

  // The models' deferred solves (OnFinish, OnResumed).
  void SolvePending(DevicePipeline& d, CalibrationHost& host, bool resuming);
  std::size_t idle_solved_at_ = 0;  // d.records_used.size() at the latest OnIdle solve
};

}  // namespace turncal::daemon
