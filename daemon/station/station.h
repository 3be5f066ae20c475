#pragma once
// One turntable station (DESIGN.md "Data flow", docs/ARCHITECTURE.md): per device a pipeline
// (daemon/station/device_pipeline.h: its sequencer, poses and noise profile), per model of each
// device a pipeline (daemon/station/model_pipeline.h: calibrator, estimate, gate, applied
// calibration). The station wires them: after every captured pose the estimates are updated on the
// solve worker, the data-level observability analysis and the publish gate run, poses and
// calibrations are persisted, and events say what happened. When a model's gate passes for the
// first time its calibration becomes active (versioned). The result has the shape DESIGN.md
// promises for `--result-out` and `turncal result --json`.
//
// Same code for live devices and replays: the Station is a ReplayTarget, and the service loop
// (issue "The daemon") will feed it from transports.

#include <atomic>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/analysis/observability.h"
#include "core/analysis/publish_gate.h"
#include "core/analysis/thermal_gate.h"
#include "core/estimation/calibrator.h"
#include "core/estimation/sensor_class.h"
#include "core/estimation/thermal_calibrator.h"
#include "core/planning/pose_planner.h"
#include "core/sequencing/sequencer.h"
#include "daemon/state/batch_file.h"
#include "daemon/station/calibration.h"
#include "daemon/station/capture_replay.h"
#include "daemon/station/device_pipeline.h"
#include "daemon/station/model_pipeline.h"
#include "protocol/sample_line.h"

namespace turncal::daemon {

// One device's own models and gate (config [[device]] models, [device.gate]); absent: the
// station's. Its nominal mount on the fixture (issue 38; [[device]] mount, or its slot's:
// docs/BATCH.md): the rotation M from the table's inner frame to its case frame that its pose
// models' context takes (C_q^r = C(eps) M); absent: the station's context's.
struct DeviceModelOptions {
  std::optional<std::vector<std::string>> models;
  std::optional<GateOptions> gate;
  std::optional<Mat3<double>> mount;
  std::string slot;  // the fixture's slot it sits in ("": none named)
};

// Where a station's poses come from (DESIGN.md "Pose sources"): announced by the controller
// (schedule files and a capture's pose events go the same way), or none at all ("free", issue
// 22): the sequencer finds the static intervals of a tumble itself and the free models (accel9,
// gyro9, magellipsoid, accmag, ...: core/modeling/free_model.h) calibrate from them
// (daemon/station/free_pipeline.h, docs/FREE.md "In the daemon").
enum class PoseSource { kAnnounced, kFree };
const char* ToString(PoseSource source);
bool ParsePoseSource(const std::string& text, PoseSource* out);

// [free]: the free pose source's own settings.
// Calibrations over temperature ("MODEL@T" in the models; [thermal]): the fit's orders and
// reference temperature, and the gate's range (docs/THERMAL.md).
struct ThermalStationOptions {
  ThermalOptions fit;
  ThermalGateOptions gate;
  SoakOptions soak;  // its set-point comes from the controller's chamber command
  // A pose whose temperature moved more than this within its window is refused (a jump in the
  // temperature channel; a 4 degC/min ramp moves 0.3 degC in a 5 s dwell).
  double max_pose_span_c = 5.0;
};

struct FreeStationOptions {
  // The gate: the share of MicroStrain's 576 latitude-longitude bins the corrected triad's
  // directions must fill, percent (0: not checked).
  double min_coverage_percent = 0.0;
  // The field's magnitude from [reference] (true), or unknown (false: the magnetometer models'
  // soft iron is then relative, |h| = 1, and the result says so).
  bool field_known = true;
  // The magnetometer's samples in motion as data (issue 37, docs/FREE.md "In motion"): every new
  // value outside the still intervals one norm equation, at most max_motion_points of them.
  bool motion = true;
  int max_motion_points = 600;  // a fit with the drift whitened grows as n^3: 0.2 s here
  // The magnetometer's bandwidth, Hz, when known (MotionOptions::mag_bandwidth_hz; 0: not
  // accounted for).
  double mag_bandwidth_hz = 0.0;
};

struct StationOptions {
  SequencerOptions sequencer;
  PoseSource pose_source = PoseSource::kAnnounced;
  FreeStationOptions free;
  ThermalStationOptions thermal;
  // Models to estimate per device; a magnetometer model only where the records carry mag. With
  // the free pose source these are free models, and an empty list means what the data carry
  // (DefaultFreeModels: accel9, gyro9 with moves, magellipsoid, accmag).
  std::vector<std::string> models = {"accel13", "mag13"};
  // Noise and tolerance class (SENSORS.md): the calibrator's noise floor and pose-to-pose offset,
  // and the gate's default tolerances.
  std::string sensor_class = "industrial";
  // false: the model before issue 19, an independent offset of the bias instability per pose
  // (kept for comparisons; its sigma are not honest in ordered plans).
  bool drift_model = true;
  // The calibrator's drift model (docs/ACCURACY.md "Drift"): the class's bias instability as a
  // Gauss-Markov process of this correlation time, and a warm-up allowance after power-on of
  // this many bias instabilities (1 sigma at the first pose) settling with warmup_tau_s.
  // Negative: the class's (100 s; no warm-up; 60 s).
  double bias_tau_s = -1.0;
  // Identify the drift's strength from the session's poses, with the class's as the prior
  // (core/estimation/drift_identify.h); false: the class's drift as it is.
  bool identify_drift = true;
  double warmup_in_instabilities = -1.0;
  double warmup_tau_s = -1.0;
  // The noise prior measured on this sensor (turncal noise on a long rest) instead of the
  // class's: white density and Gauss-Markov sigma of the accelerometer (m/s^2/sqrt(Hz), m/s^2),
  // the magnetometer's per-sample noise and Gauss-Markov sigma (device unit), and a bias random
  // walk of each (unit/sqrt(s); the class has none). Negative: the class's.
  double acc_noise_density = -1.0;
  double acc_bias_instability = -1.0;
  double mag_noise_rms = -1.0;
  double mag_bias_instability = -1.0;
  double acc_random_walk = -1.0;
  double mag_random_walk = -1.0;
  // The table's motion and what the next-pose planner minimises (core/planning/pose_planner.h).
  TableMotion table;
  // The table's rate accuracy for rate segments, relative 1 sigma ([table] rate_accuracy).
  double rate_accuracy = 1e-5;
  // What the next-pose planner minimises ([table] plan_for), and the rate segments it may
  // recommend to a gyroscope ([table] plan_rates_dps; none: the table has no rate mode). The
  // rate ripple the sequencer allows ([table] rate_ripple) is SequencerOptions::rate_steady's.
  PlanObjective plan_objective = PlanObjective::kTime;
  RatePlan plan_rates;
  ModelContext context;
  GateOptions gate;  // tolerances and min_dof replaced by the class's unless gate_tolerances_set
  bool gate_tolerances_set = false;
  std::map<std::string, DeviceModelOptions> per_device;  // by device name
  std::string fixture;  // the fixture's name ([fixture] name; "": none)
  // The batch id a new session takes ([fixture] batch; "": FIXTURE-UTCTIME). A session that
  // resumes keeps the one in its state directory's batch.json (daemon/state/batch_file.h).
  std::string batch_id;
  // Where the pose journal and the active calibrations live (daemon/state/persistence.h); empty:
  // nothing is persisted. A journal found there is replayed first: the session resumes.
  std::string state_dir;
  // Called with every activated calibration once its file in state_dir is durable, on the
  // thread that wrote it (the solve worker): the registry's outbox
  // (daemon/registry/registry_outbox.h).
  std::function<void(const nlohmann::json& calibration)> on_calibration_saved;
  bool IsValid(std::string* error) const;
  // The sensor class with this station's noise prior and drift settings in it: one rule for
  // every field above that can replace the class's value, a negative value is the class's and
  // any other replaces it (IsValid refuses a zero where only a positive value means anything: a
  // correlation time, a white density, a bias instability).
  SensorClass ResolvedSensorClass() const;
};

class Station : public ReplayTarget, private CalibrationHost {
 public:
  // Every event, as the socket will publish it ({"class":...}).
  using EventSink = std::function<void(const nlohmann::json&)>;
  // `options` must be valid.
  Station(std::vector<std::string> device_names, const StationOptions& options, EventSink sink);
  ~Station() override;

  void OnSample(int device, const Sample& sample) override;
  bool OnAnnounce(const Announcement& announcement, const std::vector<int>& devices,
                  std::string* error) override;
  // Timeouts of one device's sequencer, in that device's host clock (a replayed device's clock is
  // its capture's, so the service ticks only live devices).
  void TickDevice(int device, std::int64_t now_ns);
  // A pose for one device only (`turncal pose --device D`).
  bool AnnounceTo(int device, const Announcement& announcement, std::string* error);
  // The controller's chamber set-point (`{"cmd":"chamber","setpoint_c":...}`; nullopt: a ramp or
  // no chamber): every device's announced poses then wait for the soak to settle
  // (core/sequencing/soak.h, [thermal] soak_*).
  void SetChamber(std::optional<double> setpoint_c);
  std::optional<double> chamber_setpoint_c() const { return chamber_setpoint_c_; }
  void OnTick(std::int64_t now_ns) override;
  void OnFinish(std::int64_t now_ns) override;

  // {"class":"RESULT","devices":{NAME:{"poses":N,"models":{MODEL:{"params":{NAME:{"value","sigma"}},
  //  "rank","gate":{"pass","reasons"},"active_version",...}}}}}
  nlohmann::json Result() const;

  // A rest's noise on a device, live ({"cmd":"noise"}; docs/NOISE.md): "start" begins (or
  // begins again) summing its samples' Allan and Hadamard sums; "status" answers the analysis so
  // far; "stop" answers it, writes it to the state directory's rest_noise/DEVICE.STAMP.json and
  // ends the measurement. A NOISE reply, or an ERROR. station_noise.cc.
  nlohmann::json RestNoiseRequest(const std::string& device, const std::string& action);

  // What the live dialogue learned about a device (identity, firmware, device-side stored
  // calibration): recorded in the provenance of every calibration it gets.
  void SetDeviceIdentity(int device, nlohmann::json identity);

  // The correction of a live sample with the device's applied calibrations (MODELS.md
  // "Correction of live samples"): false when the device has none. Each triad is corrected by
  // its model's applied calibration; `versions` receives MODEL:version of those used.
  using Corrected = protocol::CorrectedSample;  // protocol/sample_line.h
  bool Correct(int device, const Sample& sample, Corrected* out, bool with_sigma = false) const;
  bool HasAppliedCalibration(int device) const;

  // Per device: poses, the pose being collected (its last progress), sample counts, and per model
  // the gate's verdict and the active version (`status` on the socket).
  nlohmann::json Status(int device) const;
  // SAMPLE on DEVICE's sensor clock (its pose records' t_sensor_start, t_sensor_end): nullopt
  // when the sample has no device time or the sequencer has seen none yet.
  std::optional<double> SensorTimeOf(int device, const Sample& sample) const;
  // The noise the device's sequencer measured (nullptr before it has).
  const NoiseProfile* NoiseOf(int device) const;

  // Makes the current estimate of DEVICE's MODEL active although the gate refused it (the
  // operator's explicit override). `who` (operator, reason, peer uid) is recorded in the
  // calibration with the gate's reasons. False with a message when there is no estimate.
  bool PublishOverride(const std::string& device, const std::string& model,
                       const nlohmann::json& who, std::string* error);

  // The next pose to capture (D-optimal over every model of the device), as NEXT_POSE.
  nlohmann::json NextPose(const std::string& device) const;
  // The next pose for the whole fixture (issue 38; docs/BATCH.md): every unit still short of a
  // gate planned together, so that the session ends at the last unit's gate; NEXT_POSE with
  // "batch" (each unit's state) and each model's "device".
  nlohmann::json NextPoseBatch() const;
  // The session's batch (issue 38; docs/BATCH.md): id, fixture, started, and each unit in order
  // with its slot, serial, poses and state -- "passed" (every gate, every calibration active;
  // "seconds": from the batch's first pose to the unit's last gate), "waiting" (why: the first
  // gate not passed, or no pose yet) or "held" (why: a wrong mount or a duplicate serial) -- and
  // the counts; "seconds_to_last_gate" once every unit passed. `status` adds each unit's link.
  nlohmann::json BatchStatus() const;
  const BatchInfo& batch() const { return batch_; }

  int DeviceIndex(const std::string& name) const;  // -1 when unknown
  // DEVICE's model MODEL (a pose model of an announced station), nullptr when it has none.
  const MeasurementModel* ModelOf(const std::string& device, const std::string& model) const;

  // Where pose updates (calibrator solve, data observability, gate) run: `work` off the event
  // loop, then `done` back on it, in order. Unset (replays, tests): both at once, inline. Work
  // still queued when the station is destroyed must be drained first; its `done` is then a no-op.
  using Executor = std::function<void(std::function<void()> work, std::function<void()> done)>;
  void SetExecutor(Executor executor);

  // Writes reports/DEVICE.html now for every device with an activation not yet in its report
  // (the service calls it before it stops; OnFinish does for replays). Reports are otherwise
  // written from TickDevice/OnTick, at most every kReportIntervalNs per device.
  void WriteDueReports();
  // The station is about to be dropped (reload, reset): the calibrations' solves and fits still
  // queued on the worker are skipped when their turn comes (their results would be discarded),
  // so draining the worker waits only for the one running and for the writes (journal, noise,
  // calibrations, reports), which all still run. abandoned_solves() counts those skipped.
  void Abandon();
  int abandoned_solves() const { return *skipped_; }
  static constexpr std::int64_t kReportIntervalNs = 60'000'000'000;
  // A live device idle this long after its latest pose solves what its calibrations deferred.
  static constexpr double kIdleSolveS = 5.0;

  // CPU time of this thread (ms) that the loop spent handling a captured pose (its answer, the
  // journal append queued, the update queued; with no executor also the solve): the last one and
  // the longest. Taken with the thread's CPU clock only when a pose is captured.
  double capture_cpu_ms_last() const { return capture_cpu_ms_last_; }
  double capture_cpu_ms_max() const { return capture_cpu_ms_max_; }

  // What reached the state directory: writes that succeeded and failed (journal appends,
  // calibrations, noise profiles, reports), and the last failure's message while the latest
  // write failed ("" once a write succeeds again). A failed write is also an ERROR event, and
  // POSE_CAPTURED / CALIBRATION_ACTIVE carry "saved": false.
  nlohmann::json PersistenceStatus() const;

  using DeviceState = DevicePipeline;

 private:
  void OnSequencerEvent(std::size_t device, const SequencerEvent& event);  // timed captures
  void HandleSequencerEvent(std::size_t device, const SequencerEvent& event);
  void WriteReport(std::size_t device, std::int64_t now_ns, bool now);
  void Update(std::size_t device, const PoseRecord& record, double t_s);
  // CalibrationHost (daemon/station/calibration.h): what the devices' calibration sets work
  // through. Activate writes the calibration's document (calibrations/DEVICE.MODEL.json, off the
  // loop), then applies it and publishes CALIBRATION_ACTIVE with "saved" (the write's outcome).
  // Defer is a calibration's computation: skipped when the station is abandoned before it starts.
  void Defer(std::function<void()> work, std::function<void()> done) override;
  void Publish(const nlohmann::json& event) override;
  void Activate(DeviceState& d, Calibration& c, double t_s,
                const nlohmann::json& override_who) override;
  void SaveNoiseProfile(DeviceState& d) override;
  // MOUNT: the device does not sit as its mount says (once per verdict).
  void PublishMount(DeviceState& d);
  void JournalMotion(DeviceState& d, std::vector<MotionValue> values) override;
  void Resume();
  void OpenSessionBatch();
  // BATCH (BatchStatus with "class") when a unit's state, why or poses changed since the last.
  void PublishBatchIfChanged();
  void LoadApplied();
  // Counts a state-directory write's outcome; publishes ERROR when it failed.
  void NoteWrite(const std::string& device, const std::string& error);
  bool EnsureJournal();  // (re)opens the journal of a session with a state directory
  // A write into the state directory on the worker, in order: never skipped.
  void DeferWrite(std::function<void()> work, std::function<void()> done);

  StationOptions options_;
  BatchInfo batch_;                 // the session's (daemon/state/batch_file.h)
  nlohmann::json batch_published_;  // the units' states the last BATCH event carried
  // The session's first pose's start (host clock, s; NaN before one): the batch's time zero.
  double batch_t0_s_ = std::numeric_limits<double>::quiet_NaN();
  SensorClass sensor_;
  EventSink sink_;
  std::vector<std::unique_ptr<DeviceState>> devices_;
  struct RestNoiseRun;  // station_noise.cc; per device, null when none is measured
  std::vector<std::shared_ptr<RestNoiseRun>> rest_noise_;
  void AddRestNoise(int device, const Sample& sample);
  void NoteRestNoiseMove(std::size_t device);
  std::shared_ptr<class PoseJournal> journal_;  // shared with queued appends
  bool journal_wanted_ = false;  // the session has a state directory: keep trying to open it
  std::uint64_t writes_ok_ = 0, writes_failed_ = 0;
  std::string write_error_;
  std::optional<double> chamber_setpoint_c_;
  bool resuming_ = false;
  Executor executor_;
  std::shared_ptr<bool> alive_ = std::make_shared<bool>(true);
  // Set by Abandon, read by the worker; the count of computations skipped, written by the worker
  // and read after the drain.
  std::shared_ptr<std::atomic<bool>> abandoned_ = std::make_shared<std::atomic<bool>>(false);
  std::shared_ptr<std::atomic<int>> skipped_ = std::make_shared<std::atomic<int>>(0);
  double capture_cpu_ms_last_ = 0.0, capture_cpu_ms_max_ = 0.0;
};

}  // namespace turncal::daemon
