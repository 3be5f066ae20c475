#pragma once
// One calibration interface (issue 35): what the station holds of a device's calibrations, and
// the one way they learn from its records. Two kinds implement it today:
//
//   pose models  (daemon/station/pose_calibrations.h, model_pipeline.h): accel13, mag13, gyro21,
//                ... each with its own calibrator, solved after every announced pose;
//   free models  (daemon/station/free_pipeline.h): accel9, magellipsoid, gyro9, accmag, ...
//                fitted together to every static interval the sequencer found itself.
//
// A calibration over temperature ("accel13@T", daemon/station/thermal_pipeline.h) is a pose model
// with its own solve, document and correction: the station (station*.cc, device_pipeline.cc)
// only ever talks to these.
//
//   Calibration     one model of one device: apply it to a sample, restore its stored document,
//                   its estimate and gate, activate it (the document and the event), report it,
//                   and the model a device write can store.
//   CalibrationSet  a device's calibrations of one kind and how they are estimated: what a
//                   captured record starts (through CalibrationHost: the solve worker, events,
//                   activation), the next pose to take, the pose source's own status.

#include <Eigen/Core>
#include <cstddef>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/analysis/publish_gate.h"
#include "core/estimation/free_motion.h"
#include "core/estimation/pose_record.h"
#include "core/estimation/sensor_class.h"
#include "core/modeling/measurement_model.h"
#include "core/planning/pose_planner.h"
#include "core/sequencing/sample.h"

namespace turncal {
class Sequencer;
struct SequencerEvent;
}  // namespace turncal

namespace turncal::daemon {

struct DevicePipeline;
struct StationOptions;

// The sample's raw triad (kTriadAcc, kTriadGyr or kTriadMag); unset when it has none.
const std::optional<Eigen::Vector3d>& RawTriad(const Sample& sample, int triad);

// What a calibration's activation writes and announces, and then applies.
struct Activation {
  nlohmann::json document;  // calibrations/DEVICE.NAME.json (the station adds "override")
  nlohmann::json event;     // CALIBRATION_ACTIVE (likewise)
  // Applies the activated version to live samples, on the loop once the document is written.
  std::function<void()> apply;
};

// The station-wide settings an activation's document records.
struct ActivationContext {
  std::string sensor_class;
  ModelContext context;  // the pose models' reference vectors and mounting
};

class Calibration {
 public:
  virtual ~Calibration() = default;

  // The name as configured: events, status, calibrations/DEVICE.NAME.json.
  virtual const std::string& name() const = 0;
  virtual int triad() const = 0;            // kTriadAcc, kTriadGyr or kTriadMag
  virtual int active_version() const = 0;   // 0: none
  virtual int applied_version() const = 0;  // the version live samples are corrected with

  // Apply: `sample`'s triad corrected by the applied calibration, with `sigma` its 1 sigma (the
  // covariance and the bias's wander since the calibration, at host time t_s), and the frame the
  // output is in. False when nothing is applied. The sample holds the triad.
  virtual bool Correct(const Sample& sample, double t_s, Eigen::Vector3d* value,
                       std::optional<Eigen::Vector3d>* sigma, const char** frame) const = 0;
  // A calibration over temperature's flag for a sample it corrects at another temperature than
  // the sample's ("below_range", "above_range", "no_temperature"); nullptr otherwise.
  virtual const char* TemperatureFlag(const Sample& sample) const {
    (void)sample;
    return nullptr;
  }

  // The document: restores the calibration stored in the state directory (applied to live
  // samples; versions go on from it). False with a message when it is unreadable.
  virtual bool ApplyStored(const nlohmann::json& stored, std::string* error) = 0;

  // The estimate and its gate: false, with the estimator's error (possibly empty), when there is
  // no estimate to activate.
  virtual bool HasEstimate(std::string* error) const = 0;
  virtual bool GatePassed() const = 0;
  virtual std::vector<std::string> GateReasons() const = 0;
  // The current estimate becomes the next active version (t_s: host time, 0 for an override).
  virtual Activation Activate(const DevicePipeline& device, const ActivationContext& context,
                              double t_s) = 0;

  // The report: the calibration's entry in `status` and in RESULT.
  virtual nlohmann::json StatusJson() const = 0;
  virtual nlohmann::json ResultJson() const = 0;

  // The write plan: the model whose parameters a device can store (nullptr: none can).
  virtual const MeasurementModel* writable_model() const { return nullptr; }
};

// The station's services a calibration set works through.
class CalibrationHost {
 public:
  virtual ~CalibrationHost() = default;
  // `work` on the solve worker (inline while resuming or without one), then `done` on the loop
  // unless the station is gone.
  virtual void Defer(std::function<void()> work, std::function<void()> done) = 0;
  virtual void Publish(const nlohmann::json& event) = 0;
  // Activates `c` (its document written, then applied and announced); `override_who` null
  // unless an operator published it against the gate.
  virtual void Activate(DevicePipeline& device, Calibration& c, double t_s,
                        const nlohmann::json& override_who) = 0;
  // The device's noise profile changed (a drift identified): its stored copy is rewritten.
  virtual void SaveNoiseProfile(DevicePipeline& device) = 0;
  // The magnetometer's new values in motion (free mode) go into the journal, one fsynced line,
  // on the worker in order with the fits queued after it.
  virtual void JournalMotion(DevicePipeline& device, std::vector<MotionValue> values) = 0;
};

class CalibrationSet {
 public:
  virtual ~CalibrationSet() = default;

  // The calibrations in the configured order (the first of a triad corrects it). A set may add
  // calibrations as it learns (the free models the data carry): indices, not pointers, are kept.
  virtual std::size_t size() const = 0;
  virtual Calibration& at(std::size_t i) = 0;
  virtual const Calibration& at(std::size_t i) const = 0;
  Calibration* Find(const std::string& name);
  const Calibration* Find(const std::string& name) const;

  // The names whose documents in the state directory are restored when the station starts, and
  // the calibration of that name (made when new).
  virtual std::vector<std::string> StoredNames() const = 0;
  virtual Calibration& Restore(const std::string& name) = 0;

  // Whether a gyroscope is estimated: its moves between poses are then evidence.
  virtual bool NeedsMoves() const = 0;
  // Called once the device's sequencer exists (the free set puts it into free mode).
  virtual void Start(Sequencer& sequencer) { (void)sequencer; }

  // A captured record is the device's latest (d.records_used holds it): the estimates it
  // changes are computed on the host's worker and gated; one whose gate passes is activated
  // unless `resuming` (a journal replayed at start: the versions stored are applied again).
  virtual void OnRecord(DevicePipeline& d, const PoseRecord& record, double t_s, bool resuming,
                        CalibrationHost& host) = 0;
  // Every sample of the device, after its sequencer has seen it (the free set keeps the
  // magnetometer's values in motion, issue 37).
  virtual void OnSample(DevicePipeline& d, const Sample& sample, CalibrationHost& host) {
    (void)d, (void)sample, (void)host;
  }
  // A resumed journal's batch of magnetometer values in motion.
  virtual void OnMotionValues(DevicePipeline& d, const std::vector<MotionValue>& values) {
    (void)d, (void)values;
  }
  // The journal's records are all in (work deferred while resuming may be done now).
  virtual void OnResumed(DevicePipeline& d, CalibrationHost& host) { (void)d, (void)host; }
  // The input has ended (a replay's capture): estimates deferred are computed now.
  virtual void OnFinish(DevicePipeline& d, CalibrationHost& host) { (void)d, (void)host; }
  // No pose has been captured for a while on a live device (the table or the chamber waits, or
  // the session has ended): estimates deferred are computed now.
  virtual void OnIdle(DevicePipeline& d, CalibrationHost& host) { (void)d, (void)host; }
  // The sequencer's other events (a free set counts the segments it skipped).
  virtual void OnSequencerEvent(const SequencerEvent& event) { (void)event; }

  // NEXT_POSE for the device (without "device").
  virtual nlohmann::json NextPose(const DevicePipeline& d, const StationOptions& options) const = 0;
  // What the next-pose planner needs of each of its calibrations (a batch's plan takes every
  // unit's together, Station::NextPoseBatch); none for a set without announced poses.
  virtual std::vector<PlanningTarget> PlanningTargets(const DevicePipeline& d,
                                                      double dwell_s) const {
    (void)d, (void)dwell_s;
    return {};
  }
  // The device's "pose_source", and the source's own entry ("free") in status and in RESULT
  // (null when it has none).
  virtual const char* pose_source() const = 0;
  virtual nlohmann::json SourceStatusJson(const DevicePipeline& d) const = 0;
  virtual nlohmann::json SourceResultJson(const DevicePipeline& d) const = 0;
};

// The set the station's pose source calls for (options.pose_source): the free models with the
// free pose source, else the pose models; `models` as configured for the device, `gate` its gate.
std::unique_ptr<CalibrationSet> MakeCalibrationSet(const std::vector<std::string>& models,
                                                   const StationOptions& options,
                                                   const SensorClass& sensor,
                                                   const GateOptions& gate);

}  // namespace turncal::daemon
