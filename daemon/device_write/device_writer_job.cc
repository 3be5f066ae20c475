// A write under way (daemon/device_write/device_writer.h): the window of the device's output
// before it, the write on the device's worker (WritableDevice::RunStoredWrite: idle, write, read
// back, save, resume, configure again) with the record of what it puts in written first, the
// window after it and the verification by measurement, then its end: the record, the history
// entry, the report, the event and the reply. A window that does not fill ends the write.
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "core/estimation/sensor_class.h"
#include "daemon/device_write/device_write_plan.h"
#include "daemon/device_write/device_writer.h"
#include "daemon/state/persistence.h"
#include "drivers/mip/mip_stored.h"
#include "drivers/transport/transport.h"

namespace turncal::daemon {

namespace {
// A window that does not fill in this long ends the verification (a device that stopped).
constexpr std::int64_t kWindowTimeoutNs = 30'000'000'000;
}  // namespace

const Sample& DeviceWriter::OnSampleOfWrittenDevice(const Sample& sample, Sample* scratch) {
  const auto it = writes_.find(sample.device);
  if (it == writes_.end()) return sample;
  Writes& writes = it->second;
  if (writes.job) OnWriteSample(&writes, sample);
  if (!writes.reexpress) return sample;
  // After a write into the device, the station sees its output in the stored values its
  // calibrations were made with (daemon/state/device_write_record.h); `raw` shows what the
  // device sends.
  *scratch = sample;
  drivers::mip::ReexpressMipOutput(writes.record->in_device, writes.record->as_if, scratch);
  return *scratch;
}

void DeviceWriter::OnWriteSample(Writes* writes, const Sample& sample) {
  Job& job = *writes->job;
  if (job.phase == Job::Phase::kBefore) {
    job.before.Add(sample);
    if (job.before.count() >= job.window) {
      // Not here: this runs inside the decoder's Push, and the write ends that decoder.
      job.phase = Job::Phase::kStarting;
      hooks_.post([this, job = writes->job] {
        auto it = writes_.find(job->args.device);
        if (it == writes_.end() || it->second.job != job || job->phase != Job::Phase::kStarting) {
          return;
        }
        StartStoredWrite(job->args.device);
      });
    }
  } else if (job.phase == Job::Phase::kAfter) {
    job.after.Add(sample);
    if (job.after.count() < job.window) return;
    VerifyAfterWrite(writes, sample);
    FinishWrite(sample.device);
  }
}

void DeviceWriter::VerifyAfterWrite(Writes* writes, const Sample& sample) {
  Job& job = *writes->job;
  // The bias wanders between the windows as the sensor class (or the configured prior) says.
  const SensorClass sensor = station_.ResolvedSensorClass();
  const double dt_s = job.after.MeanTimeS() - job.before.MeanTimeS();
  for (SensorKind kind :
       {SensorKind::kAccelerometer, SensorKind::kGyroscope, SensorKind::kMagnetometer}) {
    job.allowance.wander_sigma[TriadOfSensor(kind)] =
        WanderSigma(DriftForClass(sensor, kind).gm_sigma.x(), sensor.bias_tau_s, dt_s);
  }
  nlohmann::json verification =
      VerifyWrite(job.before, job.after, job.device_before, job.device_after, job.allowance);
  // A table that moved across the write: verified at the next captured pose instead.
  if (!verification.value("pass", false) && !job.args.restore) {
    const NoiseProfile* noise = hooks_.noise_of(sample.device);
    const MeasurementModel* model = hooks_.model_of(sample.device, job.args.model);
    bool moved = false;
    for (int triad : {kTriadAcc, kTriadGyr, kTriadMag}) {
      if (!noise || !verification["triads"].contains(TriadName(triad))) continue;
      moved = moved ||
              WindowMoved(job.before, triad, noise->sigma[static_cast<std::size_t>(triad)]) ||
              WindowMoved(job.after, triad, noise->sigma[static_cast<std::size_t>(triad)]);
    }
    if (moved && !model) {
      verification["summary"] =
          "not verified: the device moved across the write, and a calibration without a "
          "turntable has no pose to verify it at: write it with the device still (" +
          verification.value("summary", std::string()) + ")";
    } else if (moved) {
      verification["deferred"] = true;
      verification["summary"] =
          "not verified yet: the device moved across the write (its output scattered more than "
          "3 times its noise); it is verified at the next captured pose (" +
          verification.value("summary", std::string()) + ")";
      writes->at_pose = PoseCheck{job.args.model, job.version,   job.theta,
                                  job.covariance, std::string(), job.entry};
    }
  }
  job.entry["verification"] = verification;
}

// Before anything is written: what the write puts in, so that a turncald stopped mid-write knows
// at the device's next dialogue what it holds (OnIdentity). False (the write ends) when the
// record cannot be written.
bool DeviceWriter::RecordPending(const std::string& name, Job* job) {
  Writes& writes = writes_[name];
  DeviceWriteRecord pending;
  if (writes.record) pending = *writes.record;
  pending.device = name;
  pending.serial = job->serial;
  pending.as_if = job->as_if;
  pending.in_device = job->device_before;
  if (!writes.record) {
    pending.replaced = job->device_before;
    pending.operation = "none yet";
  }
  pending.pending = job->device_after;
  // What a write cut off may have done: the next dialogue finds out what the device holds.
  pending.nonvolatile_changed = pending.nonvolatile_changed || job->save;
  pending.model = job->args.restore ? pending.model : job->args.model;
  pending.version = job->version;
  std::string error;
  if (!WriteDeviceWriteRecord(state_dir_, pending, &error)) {
    job->entry["state"] = "unchanged";
    job->entry["ok"] = false;
    job->entry["error"] = "nothing was written: " + error;
    return false;
  }
  writes.record = pending;
  return true;
}

void DeviceWriter::StartStoredWrite(const std::string& name) {
  std::shared_ptr<Job> job = writes_[name].job;
  WritableDevice* device = hooks_.device(name);
  if (!device) {
    job->entry["state"] = "unchanged";
    job->entry["ok"] = false;
    job->entry["error"] = "nothing was written: " + name + " is no longer configured";
    FinishWrite(name);
    return;
  }
  job->phase = Job::Phase::kWriting;
  job->phase_started_ns = hooks_.now_ns();
  if (!RecordPending(name, job.get())) {
    FinishWrite(name);
    return;
  }
  std::string error;
  const bool started = device->RunStoredWrite(
      job->steps, job->save,
      [this, name, job](const drivers::mip::StoredWriteOutcome& outcome,
                        const nlohmann::json& identity, const std::string& configure_error) {
        OnStoredWriteDone(name, job, outcome, identity, configure_error);
      },
      &error);
  if (!started) {
    job->entry["state"] = "unchanged";
    job->entry["ok"] = false;
    job->entry["error"] = error;
    FinishWrite(name);
  }
}

void DeviceWriter::OnStoredWriteDone(const std::string& name, const std::shared_ptr<Job>& job,
                                     const drivers::mip::StoredWriteOutcome& outcome,
                                     const nlohmann::json& identity,
                                     const std::string& configure_error) {
  for (const auto& line : outcome.log) spdlog::info("{}: {}", name, line);
  job->entry["state"] = drivers::mip::ToString(outcome.state);
  job->entry["ok"] = outcome.ok();
  job->entry["error"] = outcome.error;
  job->entry["rollback_error"] = outcome.rollback_error;
  job->entry["log"] = outcome.log;
  job->entry["identity_after"] = identity;
  job->entry["configure_error"] = configure_error;
  const std::optional<StoredCalibration> now = StoredCalibrationFromIdentity(identity);
  if (now) job->entry["device_holds"] = drivers::mip::StoredCalibrationJson(*now);
  Writes& writes = writes_[name];
  if (!outcome.ok()) {
    // What the device holds now (the dialogue after the write read it back) is in effect: the
    // old values after a rollback, or whatever a failed rollback left. Without it (the dialogue
    // after the write failed too), the record keeps `pending`: the next dialogue compares.
    if (writes.record && now) {
      DeviceWriteRecord record = *writes.record;
      record.pending.reset();
      record.in_device = *now;
      std::string record_error;
      if (!WriteDeviceWriteRecord(state_dir_, record, &record_error)) {
        job->entry["record_error"] = record_error;
      }
      writes.record = record;
      writes.reexpress = record.reexpress();
    }
    spdlog::error("{}: the {} failed ({}): {}{}", name, job->entry.value("operation", ""),
                  drivers::mip::ToString(outcome.state), outcome.error,
                  outcome.rollback_error.empty()
                      ? std::string()
                      : "; the rollback failed too: " + outcome.rollback_error);
    FinishWrite(name);
    return;
  }
  DeviceWriteRecord record;
  record.device = name;
  record.serial = job->serial;
  record.model = job->args.restore ? std::string() : job->args.model;
  record.version = job->version;
  record.time = drivers::UtcNowIso8601();
  record.operation = job->args.restore ? "restore" : "write";
  record.as_if = job->as_if;
  record.in_device = outcome.read_back.value_or(job->device_after);
  record.replaced = job->device_before;
  record.saved = job->save;
  const bool was_changed = writes.record && writes.record->nonvolatile_changed;
  record.nonvolatile_changed =
      job->args.restore ? (job->save ? false : was_changed) : (was_changed || job->save);
  std::string record_error;
  if (!WriteDeviceWriteRecord(state_dir_, record, &record_error)) {
    job->entry["record_error"] = record_error;
    spdlog::error("{}: {}", name, record_error);
  }
  writes.record = record;
  writes.reexpress = record.reexpress();
  if (!configure_error.empty()) {
    job->entry["verification"] = {
        {"pass", false},
        {"summary", "not verified: the dialogue after the write failed (" + configure_error +
                        "); the device is retried, and device_writes/" + name +
                        ".json says what it holds"}};
    FinishWrite(name);
    return;
  }
  job->phase = Job::Phase::kAfter;
  job->phase_started_ns = hooks_.now_ns();
}

void DeviceWriter::FinishWrite(const std::string& name) {
  Writes& writes = writes_[name];
  std::shared_ptr<Job> job = std::move(writes.job);
  if (!job) return;
  nlohmann::json& entry = job->entry;
  std::string path, error;
  if (!WriteDeviceWriteHistory(state_dir_, name, entry, &path, &error)) {
    entry["history_error"] = error;
    spdlog::error("{}: {}", name, error);
  } else {
    entry["history"] = path;
    if (hooks_.history_written) hooks_.history_written(name, entry);
  }
  if (writes.at_pose && writes.at_pose->history.empty()) {
    writes.at_pose->history = path;
    writes.at_pose->entry = entry;
  }
  // The device's report shows the write (report/device_writes.h): rewritten now, on the loop (a
  // write is rare; the render re-solves each calibration, tens of ms).
  RewriteReport(name);
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
  hooks_.publish(message);
  if (job->reply) job->reply(message);
}

void DeviceWriter::RewriteReport(const std::string& device) const {
  std::vector<std::string> models = station_.models;
  if (const auto it = station_.per_device.find(device);
      it != station_.per_device.end() && it->second.models) {
    models = *it->second.models;
  }
  std::string error;
  if (!WriteDeviceReport(state_dir_, device, models, drivers::UtcNowIso8601(), &error)) {
    spdlog::warn("{}: {}", device, error);
  }
}

void DeviceWriter::Tick(std::int64_t now_ns) {
  for (auto& [name, writes] : writes_) {
    if (!writes.job || writes.job->phase == Job::Phase::kWriting ||
        writes.job->phase == Job::Phase::kStarting) {
      continue;
    }
    if (now_ns - writes.job->phase_started_ns < kWindowTimeoutNs) continue;
    Job& job = *writes.job;
    if (job.phase == Job::Phase::kBefore) {
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
    FinishWrite(device);
    return;  // the map may not be touched while iterating after a finish
  }
}

}  // namespace turncal::daemon
