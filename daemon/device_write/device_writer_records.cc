// What turncald learns of a write after the fact (daemon/device_write/device_writer.h): at each
// dialogue, whether the device holds what device_writes/DEVICE.json says (and so whether and from
// what its output must be re-expressed); and, for a write the device moved across, the
// verification at the next captured pose (daemon/device_write/write_verification.h VerifyAtPose).
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <cmath>

#include "core/estimation/sensor_class.h"
#include "daemon/device_write/device_write_plan.h"
#include "daemon/device_write/device_writer.h"
#include "daemon/state/atomic_file.h"
#include "drivers/mip/mip_stored.h"
#include "drivers/transport/transport.h"
#include "protocol/sequencer_json.h"

namespace turncal::daemon {

namespace {

// The device holds `actual`, not what `record` says: why, in the log. The device says what it
// holds, and re-expressing its output from any stored values into `as_if` is exact: whatever
// happened since (a write cut off, a restart without a save, another tool), the station's
// calibrations keep describing it.
void NoteUnexpectedValues(const std::string& name, const StoredCalibration& actual,
                          const nlohmann::json& identity, DeviceWriteRecord* record) {
  if (record->pending && SameStoredCalibration(actual, *record->pending)) {
    spdlog::warn(
        "{}: a write was under way when turncald stopped; the device holds what it was writing "
        "(device_writes/{}.json)",
        name, name);
  } else if (SameStoredCalibration(actual, record->as_if)) {
    spdlog::warn(
        "{}: holds the values its calibrations were made with, not those the last {} left (not "
        "saved, and the device restarted?)",
        name, record->operation);
    record->nonvolatile_changed = false;  // it started with them
  } else {
    spdlog::warn(
        "{}: holds stored values turncal did not leave there (a write cut off, or another "
        "tool); its output is re-expressed from them: {}",
        name, identity["stored_calibration"].dump());
  }
  record->replaced = record->in_device;
  record->in_device = actual;
  record->time = drivers::UtcNowIso8601();
}

}  // namespace

nlohmann::json DeviceWriter::OnIdentity(const std::string& name, const nlohmann::json& identity) {
  nlohmann::json station_identity = identity;
  const std::optional<StoredCalibration> actual = StoredCalibrationFromIdentity(identity);
  if (state_dir_.empty() || !actual) return station_identity;
  Writes& writes = writes_[name];
  // The record in memory is the latest (its file may have failed to be written); else the file.
  DeviceWriteRecord record;
  bool exists = writes.record.has_value();
  std::string error;
  if (exists) {
    record = *writes.record;
  } else if (!ReadDeviceWriteRecord(state_dir_, name, &record, &exists, &error)) {
    spdlog::error("{}: {}; the device's output is taken as it is", name, error);
    exists = false;
  }
  const std::string serial = identity.value("serial", "");
  if (exists && serial != record.serial) {
    spdlog::warn("{}: device_writes/{}.json is of serial {}, the device is {}: not used", name,
                 name, record.serial, serial);
    writes.record.reset();
    writes.reexpress = false;
  } else if (exists && writes.job) {
    // A write under way: its own end updates the record.
    writes.record = record;
    writes.reexpress = record.reexpress();
  } else if (exists) {
    bool changed = record.pending.has_value();
    if (!SameStoredCalibration(*actual, record.in_device)) {
      changed = true;
      NoteUnexpectedValues(name, *actual, identity, &record);
    }
    record.pending.reset();
    if (changed && !WriteDeviceWriteRecord(state_dir_, record, &error)) {
      spdlog::error("{}: {}", name, error);
    }
    writes.record = record;
    writes.reexpress = record.reexpress();
  }
  if (writes.reexpress && writes.record) {
    station_identity["stored_calibration"] =
        drivers::mip::StoredCalibrationJson(writes.record->as_if);
    station_identity["stored_calibration_in_device"] = identity["stored_calibration"];
    station_identity["output_reexpressed"] =
        "turncald re-expresses the output in stored_calibration (device_writes/" + name + ".json)";
    spdlog::info(
        "{}: its output is re-expressed in the stored values its calibrations were made with "
        "(the {} of {})",
        name, writes.record->operation, writes.record->time);
  }
  return station_identity;
}

void DeviceWriter::OnPoseCaptured(const nlohmann::json& event) {
  const std::string device = event.value("device", "");
  auto it = writes_.find(device);
  if (it == writes_.end() || !it->second.at_pose || !it->second.record) return;
  Writes& writes = it->second;
  PoseCheck check = *writes.at_pose;
  writes.at_pose.reset();
  PoseRecord record;
  std::string error;
  nlohmann::json verification;
  const MeasurementModel* model = hooks_.model_of(device, check.model);
  if (!event.contains("record") || !protocol::ParsePoseRecord(event["record"], &record, &error)) {
    verification = {{"pass", false}, {"summary", "not verified: the pose's record: " + error}};
  } else if (!model ||
             check.theta.size() != static_cast<Eigen::Index>(model->parameters().size())) {
    verification = {{"pass", false},
                    {"summary", fmt::format("not verified: {} is no longer a model of {}",
                                            check.model, device)}};
  } else {
    const SensorClass sensor = station_.ResolvedSensorClass();
    const double instability = DriftForClass(sensor, model->sensor()).gm_sigma.x();
    // The bias since the calibration: at most the Gauss-Markov process's whole spread.
    verification = VerifyAtPose(*model, check.theta, check.covariance, record, writes.record->as_if,
                                writes.record->in_device, instability * std::sqrt(2.0));
  }
  verification["index"] = event.value("index", -1);
  check.entry["verification_at_pose"] = verification;
  if (!check.history.empty() &&
      !WriteFileAtomically(check.history, check.entry.dump(1) + "\n", &error)) {
    spdlog::error("{}: {}", device, error);
  } else if (!check.history.empty() && hooks_.history_written) {
    hooks_.history_written(device, check.entry);  // the registry's row of this write, completed
  }
  spdlog::log(verification.value("pass", false) ? spdlog::level::info : spdlog::level::err,
              "{}: {} v{} written into the device: {}", device, check.model, check.version,
              verification.value("summary", std::string()));
  RewriteReport(device);
  hooks_.publish({{"class", "DEVICE_WRITE_VERIFIED"},
                  {"device", device},
                  {"model", check.model},
                  {"version", check.version},
                  {"verification", verification},
                  {"history", check.history}});
}

}  // namespace turncal::daemon
