#pragma once
// One device in the station: its sequencer (stillness, poses, noise profile), its calibrations
// (daemon/station/calibration.h), the poses and records its calibrations are made from, and what
// the device said about itself. The station (daemon/station/station.h) feeds it samples and
// announcements and wires its events to the models, persistence and subscribers.

#include <cstdint>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/analysis/mount_check.h"
#include "core/analysis/publish_gate.h"
#include "core/planning/pose_planner.h"
#include "core/sequencing/sequencer.h"
#include "daemon/station/calibration.h"
#include "daemon/station/model_pipeline.h"

namespace turncal::daemon {

struct DevicePipeline {
  std::string name;
  std::unique_ptr<Sequencer> sequencer;
  // Its calibrations (daemon/station/calibration.h): the pose models, or the free pose source's.
  std::unique_ptr<CalibrationSet> calibrations;
  std::vector<TablePose> poses_used;
  std::vector<PoseRecord> records_used;  // the same poses' records (a calibration's evidence)
  int poses = 0;
  bool noise_stored = false;  // the sequencer uses the profile kept in the state directory
  GateOptions gate;           // the station's, or the device's own
  // Its pose models' context: the station's, with the device's own nominal mount (issue 38:
  // [[device]] mount or its fixture slot's), the slot's name, and whether the unit sits as that
  // mount says (core/analysis/mount_check.h), checked from its accelerometer at every static
  // pose. While it does not, its calibrations are held (not activated): the operator fixes the
  // configuration and reloads, and the poses already captured are used again from the journal.
  ModelContext context;
  std::string slot;
  bool mount_configured = false;
  std::vector<MountObservation> mount_observations;
  MountCheck mount_check;
  bool mount_wrong_published = false;  // the MOUNT event for the current verdict was sent
  nlohmann::json identity;             // from the device dialogue (null in replays)
  // Another device of the station that reported the same serial first ("": none): this one's
  // calibrations are held (Station::SetDeviceIdentity).
  std::string duplicate_serial_of;
  // When every calibration of the unit had passed its gate and was activated (session time, s;
  // NaN: not yet): the batch's summary counts the unit's time from it (issue 38).
  double passed_t_s = std::numeric_limits<double>::quiet_NaN();
  nlohmann::json current;  // the pose being collected: its last sequencer event
  // reports/NAME.html is rewritten after an activation, at most every kReportIntervalNs (the
  // render re-solves the calibration pose by pose: tens of ms on the worker).
  bool report_due = false;
  std::int64_t report_written_ns = std::numeric_limits<std::int64_t>::min() / 2;

  // The sequencer's options for a device of the station: the station's, with the bias wander
  // the stillness and creep tests allow for (the sensor class's drift, or the configured one).
  static SequencerOptions SequencerOptionsFor(const StationOptions& options,
                                              const SensorClass& sensor);

  // Records the drift model `m` identified in the noise profile (the stillness tests allow for
  // it); true when the profile's stored copy should be rewritten (the scale moved by more than
  // 1 %, or the triad had none).
  bool RecordIdentifiedDrift(const ModelPipeline& m);

  // The rest the moves captured so far spanned besides the table's motion and settling at
  // `motion`'s rates (the mean, at least 0), for the planner's moves; `fallback` without one.
  double MoveRestSeconds(const TableMotion& motion, double fallback) const;

  // The device's entry in `status` and in RESULT.
  // The sensor's temperature, its rate of change and the chamber's soak (status "temperature").
  nlohmann::json TemperatureJson() const;
  nlohmann::json StatusJson() const;
  nlohmann::json ResultJson() const;
  // The sequencer's moves between static poses: enabled, taken (handed to a record), dropped and
  // why the latest was.
  nlohmann::json MovesJson() const;
  // The mount: configured (its axes or angles), slot, and the check's verdict with its words
  // (status and RESULT "mount"; the MOUNT event).
  nlohmann::json MountJson() const;
  // The check's verdict for an operator: "" while the unit sits as configured, else what is
  // wrong and what to configure ("slot 3 looks rotated 90 deg about its +z: ...").
  std::string MountProblem() const;
  // The serial number the device's dialogue reported (a MIP's serial, an Xbus device id); "" if
  // none (a replay).
  std::string Serial() const;
  // Adds a static pose's accelerometer mean to the mount check; true when the verdict changed.
  bool CheckMountWith(const PoseRecord& record);
};

}  // namespace turncal::daemon
