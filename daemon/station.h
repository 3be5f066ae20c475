#pragma once
// One turntable station (DESIGN.md "Data flow"): per device a Sequencer, and per model a
// Calibrator; after every captured pose the estimates are updated, the data-level observability
// analysis and the publish gate run, and events say what happened. When a model's gate passes for
// the first time its calibration becomes active (versioned). The result has the shape DESIGN.md
// promises for `--result-out` and `turncal result --json`.
//
// Same code for live devices and replays: the Station is a ReplayTarget, and the service loop
// (issue "The daemon") will feed it from transports.

#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/calibrator.h"
#include "core/observability.h"
#include "core/publish_gate.h"
#include "core/sequencer.h"
#include "core/synthetic.h"
#include "daemon/capture_replay.h"

namespace turncal::daemon {

struct StationOptions {
  SequencerOptions sequencer;
  // Models to estimate per device; a magnetometer model only where the records carry mag.
  std::vector<std::string> models = {"accel13", "mag13"};
  // Noise and tolerance class (SENSORS.md): the calibrator's noise floor and pose-to-pose offset,
  // and the gate's default tolerances.
  std::string sensor_class = "industrial";
  ModelContext context;
  GateOptions gate;  // tolerances replaced by the class's unless gate_tolerances_set
  bool gate_tolerances_set = false;
  // Where the pose journal and the active calibrations live (daemon/persistence.h); empty:
  // nothing is persisted. A journal found there is replayed first: the session resumes.
  std::string state_dir;
  bool IsValid(std::string* error) const;
};

class Station : public ReplayTarget {
 public:
  // Every event, as the socket will publish it ({"class":...}).
  using EventSink = std::function<void(const nlohmann::json&)>;
  // `options` must be valid.
  Station(std::vector<std::string> device_names, const StationOptions& options, EventSink sink);
  ~Station() override;

  void OnSample(int device, const Sample& sample) override;
  bool OnAnnounce(const Announcement& announcement, std::string* error) override;
  void OnTick(std::int64_t now_ns) override;
  void OnFinish(std::int64_t now_ns) override;

  // {"class":"RESULT","devices":{NAME:{"poses":N,"models":{MODEL:{"params":{NAME:{"value","sigma"}},
  //  "rank","gate":{"pass","reasons"},"active_version",...}}}}}
  nlohmann::json Result() const;

  struct ModelState;
  struct DeviceState;

 private:
  void OnSequencerEvent(std::size_t device, const SequencerEvent& event);
  void Update(std::size_t device, const PoseRecord& record, double t_s);
  void Resume();
  void Publish(const nlohmann::json& event);
  nlohmann::json CalibrationJson(const DeviceState& d, const ModelState& m) const;

  StationOptions options_;
  SensorClass sensor_;
  EventSink sink_;
  std::vector<std::unique_ptr<DeviceState>> devices_;
  std::unique_ptr<class PoseJournal> journal_;
  bool resuming_ = false;
};

}  // namespace turncal::daemon
