// Issue 23: a device write's end and what turncald learns of it after the fact -- the history
// entry, the reply and the report when a write ends (or its window times out); at each
// configuration, whether the device holds what device_writes/DEVICE.json says (and so whether its
// output must be re-expressed); and, for a write the device moved across, the verification at the
// next captured pose (daemon/device_write.h VerifyAtPose).
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "core/estimation/sensor_class.h"
#include "daemon/atomic_file.h"
#include "daemon/device_write_plan.h"
#include "daemon/persistence.h"
#include "daemon/service.h"
#include "daemon/service_device_write_job.h"
#include "drivers/mip/mip_stored.h"
#include "drivers/transport/transport.h"
#include "protocol/sequencer_json.h"

namespace turncal::daemon {

namespace {
// A window that does not fill in this long ends the verification (a device that stopped).
constexpr std::int64_t kWindowTimeoutNs = 30'000'000'000;
}  // namespace

void Service::FinishDeviceWrite(const std::string& name, nlohmann::json reply) {
  DeviceWrites& writes = writes_[name];
  std::shared_ptr<DeviceWriteJob> job = std::move(writes.job);
  if (!job) return;
  nlohmann::json& entry = job->entry;
  if (!reply.is_null()) entry["error"] = reply;
  std::string path, error;
  if (!WriteDeviceWriteHistory(options_.state_dir, name, entry, &path, &error)) {
    entry["history_error"] = error;
    spdlog::error("{}: {}", name, error);
  } else {
    entry["history"] = path;
    QueueDeviceWrite(name, entry);
  }
  if (writes.at_pose && writes.at_pose->history.empty()) {
    writes.at_pose->history = path;
    writes.at_pose->entry = entry;
  }
  // The device's report shows the write (report/device_writes.h): rewritten now, on the loop (a
  // write is rare; the render re-solves each calibration, tens of ms).
  std::vector<std::string> models = options_.station.models;
  if (const auto it = options_.station.per_device.find(name);
      it != options_.station.per_device.end() && it->second.models) {
    models = *it->second.models;
  }
  std::string report_error;
  if (!WriteDeviceReport(options_.state_dir, name, models, drivers::UtcNowIso8601(),
                         &report_error)) {
    spdlog::warn("{}: {}", name, report_error);
  }
  const bool ok = entry.value("ok", false);
  const nlohmann::json verification = entry.value("verification", nlohmann::json());
  spdlog::log(ok ? spdlog::level::info : spdlog::level::err, "{}: {} {}: {}{}", name,
              entry.value("operation", ""), entry.value("state", ""),
              ok ? std::string("done") : entry.value("error", std::string("failed")),
              verification.is_object() ? "; " + verification.value("summary", std::string())
                                       : std::string());
  nlohmann::json message = entry;
  message["class"] = "DEVICE_WRITTEN";
  message.erase("identity_after");
  OnEvent(message);
  if (auto client = job->client.lock()) {
    if (!job->id.is_null()) message["id"] = job->id;
    client->Reply(message);
  }
}

void Service::TickDeviceWrites(std::int64_t now_ns) {
  for (auto& [name, writes] : writes_) {
    if (!writes.job || writes.job->phase == DeviceWriteJob::Phase::kWriting ||
        writes.job->phase == DeviceWriteJob::Phase::kStarting) {
      continue;
    }
    if (now_ns - writes.job->phase_started_ns < kWindowTimeoutNs) continue;
    DeviceWriteJob& job = *writes.job;
    if (job.phase == DeviceWriteJob::Phase::kBefore) {
      job.entry["state"] = "unchanged";
      job.entry["ok"] = false;
      job.entry["error"] = fmt::format(
          "nothing was written: {} sent {} of the {} samples averaged before a write in {} s", name,
          job.before.count(), job.window, kWindowTimeoutNs / 1'000'000'000);
    } else {
      job.entry["verification"] = {
          {"pass", false},
          {"summary",
           fmt::format("not verified: {} sent {} of {} samples after the write in {} s", name,
                       job.after.count(), job.window, kWindowTimeoutNs / 1'000'000'000)}};
    }
    const std::string device = name;
    FinishDeviceWrite(device, nullptr);
    return;  // the map may not be touched while iterating after a finish
  }
}

void Service::VerifyWriteAtPose(const nlohmann::json& event) {
  const std::string device = event.value("device", "");
  auto it = writes_.find(device);
  if (it == writes_.end() || !it->second.at_pose || !it->second.record || !station_) return;
  DeviceWrites& writes = it->second;
  DeviceWrites::PoseCheckT check = *writes.at_pose;
  writes.at_pose.reset();
  PoseRecord record;
  std::string error;
  nlohmann::json verification;
  const MeasurementModel* model = station_->ModelOf(device, check.model);
  if (!event.contains("record") || !protocol::ParsePoseRecord(event["record"], &record, &error)) {
    verification = {{"pass", false}, {"summary", "not verified: the pose's record: " + error}};
  } else if (!model ||
             check.theta.size() != static_cast<Eigen::Index>(model->parameters().size())) {
    verification = {{"pass", false},
                    {"summary", fmt::format("not verified: {} is no longer a model of {}",
                                            check.model, device)}};
  } else {
    SensorClass sensor;
    if (!SensorClassByName(options_.station.sensor_class, &sensor)) sensor = IndustrialClass();
    const StationOptions& so = options_.station;
    const double instability =
        model->sensor() == SensorKind::kAccelerometer
            ? (so.acc_bias_instability >= 0 ? so.acc_bias_instability : sensor.acc_bias_instability)
        : model->sensor() == SensorKind::kMagnetometer
            ? (so.mag_bias_instability >= 0 ? so.mag_bias_instability : sensor.mag_bias_instability)
            : sensor.gyr_bias_instability;
    // The bias since the calibration: at most the Gauss-Markov process's whole spread.
    verification = VerifyAtPose(*model, check.theta, check.covariance, record, writes.record->as_if,
                                writes.record->in_device, instability * std::sqrt(2.0));
  }
  verification["index"] = event.value("index", -1);
  check.entry["verification_at_pose"] = verification;
  if (!check.history.empty() &&
      !WriteFileAtomically(check.history, check.entry.dump(1) + "\n", &error)) {
    spdlog::error("{}: {}", device, error);
  } else if (!check.history.empty()) {
    QueueDeviceWrite(device, check.entry);  // the registry's row of this write, completed
  }
  spdlog::log(verification.value("pass", false) ? spdlog::level::info : spdlog::level::err,
              "{}: {} v{} written into the device: {}", device, check.model, check.version,
              verification.value("summary", std::string()));
  std::string report_error;
  std::vector<std::string> models = options_.station.models;
  if (const auto pd = options_.station.per_device.find(device);
      pd != options_.station.per_device.end() && pd->second.models) {
    models = *pd->second.models;
  }
  if (!WriteDeviceReport(options_.state_dir, device, models, drivers::UtcNowIso8601(),
                         &report_error)) {
    spdlog::warn("{}: {}", device, report_error);
  }
  OnEvent({{"class", "DEVICE_WRITE_VERIFIED"},
           {"device", device},
           {"model", check.model},
           {"version", check.version},
           {"verification", verification},
           {"history", check.history}});
}

void Service::QueueDeviceWrite(const std::string& device, const nlohmann::json& entry) {
  if (!registry_) return;
  nlohmann::json identity = {{"serial", entry.value("serial", "")}};
  for (const auto& d : devices_) {
    if (d->spec().name != device) continue;
    const nlohmann::json live = d->Status()["identity"];
    if (live.is_object()) identity = live;
  }
  std::string error;
  if (!registry_->AddDeviceWrite(entry, identity, entry.value("history", ""), &error)) {
    spdlog::error("{}: {}", device, error);
  }
}

void Service::OnDeviceIdentity(std::size_t index, const nlohmann::json& identity) {
  const std::string& name = devices_[index]->spec().name;
  nlohmann::json station_identity = identity;
  const std::optional<StoredCalibration> actual = StoredCalibrationFromIdentity(identity);
  if (!options_.state_dir.empty() && actual) {
    DeviceWrites& writes = writes_[name];
    // The record in memory is the latest (its file may have failed to be written); else the file.
    DeviceWriteRecord record;
    bool exists = writes.record.has_value();
    std::string error;
    if (exists) {
      record = *writes.record;
    } else if (!ReadDeviceWriteRecord(options_.state_dir, name, &record, &exists, &error)) {
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
      // The device says what it holds, and re-expressing its output from any stored values into
      // `as_if` is exact: whatever happened since (a write cut off, a restart without a save,
      // another tool), the station's calibrations keep describing it.
      bool changed = record.pending.has_value();
      if (!SameStoredCalibration(*actual, record.in_device)) {
        changed = true;
        if (record.pending && SameStoredCalibration(*actual, *record.pending)) {
          spdlog::warn(
              "{}: a write was under way when turncald stopped; the device holds what "
              "it was writing (device_writes/{}.json)",
              name, name);
        } else if (SameStoredCalibration(*actual, record.as_if)) {
          spdlog::warn(
              "{}: holds the values its calibrations were made with, not those the last "
              "{} left (not saved, and the device restarted?)",
              name, record.operation);
          record.nonvolatile_changed = false;  // it started with them
        } else {
          spdlog::warn(
              "{}: holds stored values turncal did not leave there (a write cut off, or "
              "another tool); its output is re-expressed from them: {}",
              name, identity["stored_calibration"].dump());
        }
        record.replaced = record.in_device;
        record.in_device = *actual;
        record.time = drivers::UtcNowIso8601();
      }
      record.pending.reset();
      if (changed && !WriteDeviceWriteRecord(options_.state_dir, record, &error)) {
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
          "turncald re-expresses the output in stored_calibration (device_writes/" + name +
          ".json)";
      spdlog::info(
          "{}: its output is re-expressed in the stored values its calibrations were made "
          "with (the {} of {})",
          name, writes.record->operation, writes.record->time);
    }
  }
  if (station_) station_->SetDeviceIdentity(static_cast<int>(index), station_identity);
}

}  // namespace turncal::daemon
