// device_write (issue 23, docs/protocol.md "Writing a calibration into the device"): a device's
// active calibration into its stored calibration, or (restore) what it held before turncal wrote
// into it. The plan first (daemon/device_write_plan.h); then a window of the device's output, the
// write on the device's worker (LiveDevice::RunStoredWrite: idle, write, read back, save, resume,
// configure again), a window after it, the verification by measurement, the record in the state
// directory (daemon/device_write.h) and the reply. Every step goes to the log and the history.
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <Eigen/LU>
#include <algorithm>
#include <boost/asio/post.hpp>
#include <cmath>

#include "core/estimation/sensor_class.h"
#include "core/sequencing/stillness.h"
#include "daemon/device_write_plan.h"
#include "daemon/persistence.h"
#include "daemon/service.h"
#include "daemon/service_device_write_job.h"
#include "drivers/mip/mip_stored.h"
#include "drivers/mip/mip_stored_write.h"
#include "drivers/transport/transport.h"
#include "protocol/free_json.h"
#include "protocol/messages.h"

namespace turncal::daemon {

namespace {

// The device's output is averaged over this long before and after a write (at least 20 samples,
// at most 1000).
constexpr double kWindowSeconds = 2.0;

std::string Join(const std::vector<std::string>& parts, const char* separator) {
  std::string out;
  for (const auto& p : parts) out += (out.empty() ? "" : separator) + p;
  return out;
}

}  // namespace

void Service::HandleDeviceWrite(const std::shared_ptr<ClientSession>& client,
                                const nlohmann::json& request, const nlohmann::json& id) {
  const auto reply = [&](nlohmann::json message) {
    if (!id.is_null()) message["id"] = id;
    client->Reply(message);
  };
  const auto fail = [&](const std::string& message, const nlohmann::json& plan = nullptr) {
    nlohmann::json e = protocol::ErrorMessage("device_write: " + message);
    if (!plan.is_null()) e["plan"] = plan;
    reply(e);
  };
  protocol::DeviceWriteArgs args;
  std::string why;
  if (!protocol::ParseDeviceWriteRequest(request, &args, &why)) {
    reply(protocol::ErrorMessage(why));
    return;
  }
  if (options_.state_dir.empty()) {
    fail("turncald has no state directory, and the values a write replaces must be kept there");
    return;
  }
  std::size_t index = devices_.size();
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    if (devices_[i]->spec().name == args.device) index = i;
  }
  if (index == devices_.size() || !station_) {
    fail("no device '" + args.device + "'");
    return;
  }
  LiveDevice& device = *devices_[index];
  DeviceWrites& writes = writes_[args.device];
  if (writes.job) {
    fail("a write into " + args.device + " is under way");
    return;
  }
  const nlohmann::json identity = device.Status()["identity"];
  const std::optional<StoredCalibration> actual = StoredCalibrationFromIdentity(identity);
  // What the station's calibrations see the output in.
  const StoredCalibration as_if_now =
      writes.reexpress ? writes.record->as_if : actual.value_or(StoredCalibration{});

  auto job = std::make_shared<DeviceWriteJob>();
  job->client = client;
  job->id = id;
  job->args = args;
  job->serial = identity.is_object() ? identity.value("serial", "") : "";
  std::vector<std::string> refusals;
  if (!args.restore) {
    nlohmann::json calibration;
    if (!ReadActiveCalibration(options_.state_dir, args.device, args.model, &calibration)) {
      fail(
          fmt::format("{} has no active calibration of {} (one that passed its gate, or was "
                      "published)",
                      args.device, args.model));
      return;
    }
    DeviceWriteRequest q;
    q.device = args.device;
    q.protocol = device.spec().protocol;
    q.serial_now = job->serial;
    q.stored_now = as_if_now;
    q.transform = args.transform;
    // A pose model's calibration, or a free one's (issue 22: accel9, gyro9, gyro9g,
    // magellipsoid, magsphere); the free model lives until the plan is made.
    std::unique_ptr<FreeModel> free_model;
    if (protocol::IsFreeCalibration(calibration)) {
      protocol::FreeCalibrationDocument doc;
      if (!protocol::ParseFreeCalibration(calibration, &doc, &why)) {
        fail("the active calibration of " + args.model + ": " + why);
        return;
      }
      if (doc.model == "accmag") {
        fail(
            "accmag calibrates two triads and the rotation between them: write accel9 and "
            "magellipsoid (or magsphere) instead");
        return;
      }
      free_model = MakeFreeModel(doc.model, doc.context, &why);
      if (!free_model) {
        fail(why);
        return;
      }
      const double scale =
          free_model->sensor() == SensorKind::kAccelerometer ? doc.context.gravity_mps2
          : free_model->sensor() == SensorKind::kMagnetometer && doc.context.field_magnitude > 0
              ? doc.context.field_magnitude
              : 1.0;
      q.correction = CorrectionOf(*free_model, scale);
      q.theta = doc.theta;
      q.covariance = doc.covariance;
    } else {
      const MeasurementModel* model = station_->ModelOf(args.device, args.model);
      if (!model) {
        fail(fmt::format("{} has no model '{}' in this station", args.device, args.model));
        return;
      }
      q.model = model;
      if (!CalibrationValues(*model, calibration, &q.theta, &q.covariance)) {
        fail("the active calibration's document lacks a parameter of " + args.model);
        return;
      }
    }
    q.version = calibration.value("version", 0);
    q.gate_passed = calibration.contains("gate") && calibration["gate"].is_object() &&
                    calibration["gate"].value("pass", false) && !calibration.contains("override");
    const nlohmann::json then = calibration.contains("provenance") &&
                                        calibration["provenance"].is_object() &&
                                        calibration["provenance"].contains("device_identity")
                                    ? calibration["provenance"]["device_identity"]
                                    : nlohmann::json();
    q.serial_then = then.is_object() ? then.value("serial", "") : "";
    q.stored_then = StoredCalibrationFromIdentity(then);
    DeviceWritePlan plan;
    if (!actual && q.protocol == drivers::Protocol::kMip) {
      // Nothing to compose with: the device never said what it stores.
      job->plan = {{"device", args.device},
                   {"model", args.model},
                   {"version", calibration.value("version", 0)},
                   {"serial", job->serial},
                   {"writes", nlohmann::json::array()}};
      refusals.push_back(args.device + " has not told turncald what it stores (state " +
                         device.state() +
                         "; a device turncald only listens to, configure = false, never does): "
                         "nothing to compose the values with");
    } else {
      plan = PlanDeviceWrite(q);
      // The plan composes with what the station's calibrations see (as_if); a device that holds
      // another transform (an earlier --transform) outputs the triad turned by M_dev M_as_if^-1,
      // so the stream corrects its output with A M_as_if M_dev^-1.
      const Eigen::Matrix3d unit = Eigen::Matrix3d::Identity();
      const Eigen::Matrix3d m_dev = actual->transform.value_or(unit);
      const Eigen::Matrix3d m_as_if = as_if_now.transform.value_or(unit);
      if (!args.transform && m_dev != m_as_if) {
        plan.stream.A = plan.stream.A * m_as_if * m_dev.inverse();
      }
      job->plan = ToJson(plan);
      refusals = plan.refusals;
    }
    job->plan["operation"] = "write";
    if (args.version && *args.version != q.version) {
      refusals.push_back(fmt::format(
          "the plan shown was for version {}; version {} is active now: look at it again",
          *args.version, q.version));
    }
    job->version = q.version;
    job->theta = q.theta;
    job->covariance = q.covariance;
    job->device_before = actual.value_or(StoredCalibration{});
    job->device_after = job->device_before;
    for (const StoredWrite& w : plan.writes) {
      job->steps.push_back(
          {w.descriptor, w.to_write, drivers::mip::StoredValues(job->device_before, w.descriptor)});
      drivers::mip::SetStoredValues(&job->device_after, w.descriptor, w.to_write);
    }
    job->as_if = as_if_now;
    job->save = args.save;
  } else {
    if (!writes.record) {
      bool exists = false;
      DeviceWriteRecord record;
      if (!ReadDeviceWriteRecord(options_.state_dir, args.device, &record, &exists, &why)) {
        fail(why);
        return;
      }
      if (exists) writes.record = record;
    }
    if (!writes.record) {
      fail("nothing to restore: no write into " + args.device + " is recorded in " +
           options_.state_dir + "/device_writes");
      return;
    }
    const DeviceWriteRecord& r = *writes.record;
    job->device_before = actual.value_or(StoredCalibration{});
    job->device_after = r.as_if;
    job->as_if = r.as_if;
    job->version = r.version;
    job->save = args.save || r.nonvolatile_changed;
    nlohmann::json list = nlohmann::json::array();
    for (const std::uint8_t d : {0x37, 0x38, 0x3A, 0x3B, 0x33}) {
      const auto now = drivers::mip::StoredValues(job->device_before, d);
      const auto back = drivers::mip::StoredValues(r.as_if, d);
      if (back.empty() || now == back) continue;
      job->steps.push_back({d, back, now});
      list.push_back({{"quantity", drivers::mip::StoredQuantityKey(d)},
                      {"name", drivers::mip::StoredQuantityName(d)},
                      {"descriptor", fmt::format("0x0C 0x{:02X}", d)},
                      {"stored", JsonNumbers(now)},
                      {"to_write", JsonNumbers(back)},
                      {"unit", drivers::mip::StoredQuantityUnit(d)}});
    }
    if (!actual) refusals.push_back(args.device + " has not told its stored calibration yet");
    if (actual && !SameStoredCalibration(*actual, r.in_device)) {
      refusals.push_back(args.device +
                         " holds other values than the last write left: nothing is restored "
                         "(device_writes/" +
                         args.device + ".json has what was written)");
    }
    if (!job->serial.empty() && job->serial != r.serial) {
      refusals.push_back(fmt::format("the record is of serial {}; {} is serial {}", r.serial,
                                     args.device, job->serial));
    }
    if (job->steps.empty() && refusals.empty()) {
      refusals.push_back(args.device +
                         " already holds the values its calibrations were made "
                         "with: nothing to restore");
    }
    job->plan = {{"device", args.device},
                 {"operation", "restore"},
                 {"serial", job->serial},
                 {"restores_write", {{"model", r.model}, {"version", r.version}, {"time", r.time}}},
                 {"writes", list},
                 {"save", job->save},
                 {"ok", refusals.empty()},
                 {"refusals", refusals}};
  }
  if (writes.reexpress && actual) {
    job->plan["device_holds"] = drivers::mip::StoredCalibrationJson(*actual);
  }
  job->plan["refusals"] = refusals;
  job->plan["ok"] = refusals.empty();
  if (args.dry_run) {
    reply({{"class", "DEVICE_WRITE_PLAN"}, {"dry_run", true}, {"plan", job->plan}});
    return;
  }
  if (!refusals.empty()) {
    fail("refused: " + Join(refusals, "; "), job->plan);
    return;
  }
  if (device.state() != "streaming") {
    fail(fmt::format("{} is {}, not streaming", args.device, device.state()));
    return;
  }
  const double rate_hz = identity.is_object() && identity.value("rate_hz", 0.0) > 0
                             ? identity.value("rate_hz", 0.0)
                             : DefaultRateHz(device.spec().protocol);
  job->window = std::clamp(static_cast<int>(std::lround(rate_hz * kWindowSeconds)), 20, 1000);
  job->phase_started_ns = drivers::MonotonicNowNs();
  job->entry = {{"schema", 1},
                {"class", "DEVICE_WRITE"},
                {"device", args.device},
                {"operation", args.restore ? "restore" : "write"},
                {"model", args.model},
                {"version", job->version},
                {"serial", job->serial},
                {"save", job->save},
                {"time", drivers::UtcNowIso8601()},
                {"uid", client->uid()},
                {"plan", job->plan}};
  writes.job = job;
  spdlog::info("{}: {} {} v{} requested by uid {}: averaging {} samples of the output first",
               args.device, args.restore ? "restore" : "write", args.model, job->version,
               client->uid(), job->window);
}

void Service::OnWriteSample(std::size_t device, const Sample& sample) {
  DeviceWrites& writes = writes_[sample.device];
  DeviceWriteJob& job = *writes.job;
  if (job.phase == DeviceWriteJob::Phase::kBefore) {
    job.before.Add(sample);
    if (job.before.count() >= job.window) {
      // Not here: this runs inside the decoder's Push, and the write ends that decoder.
      job.phase = DeviceWriteJob::Phase::kStarting;
      boost::asio::post(io_, [this, job = writes.job] {
        auto it = writes_.find(job->args.device);
        if (it == writes_.end() || it->second.job != job ||
            job->phase != DeviceWriteJob::Phase::kStarting) {
          return;
        }
        StartStoredWrite(job->args.device);
      });
    }
  } else if (job.phase == DeviceWriteJob::Phase::kAfter) {
    job.after.Add(sample);
    if (job.after.count() < job.window) return;
    // The bias wanders between the windows as the sensor class (or the configured prior) says.
    SensorClass sensor;
    if (!SensorClassByName(options_.station.sensor_class, &sensor)) sensor = IndustrialClass();
    const StationOptions& so = options_.station;
    const double tau_s = so.bias_tau_s > 0 ? so.bias_tau_s : sensor.bias_tau_s;
    const double dt_s = job.after.MeanTimeS() - job.before.MeanTimeS();
    job.allowance.wander_sigma[kTriadAcc] = WanderSigma(
        so.acc_bias_instability >= 0 ? so.acc_bias_instability : sensor.acc_bias_instability, tau_s,
        dt_s);
    job.allowance.wander_sigma[kTriadGyr] = WanderSigma(sensor.gyr_bias_instability, tau_s, dt_s);
    job.allowance.wander_sigma[kTriadMag] = WanderSigma(
        so.mag_bias_instability >= 0 ? so.mag_bias_instability : sensor.mag_bias_instability, tau_s,
        dt_s);
    nlohmann::json verification =
        VerifyWrite(job.before, job.after, job.device_before, job.device_after, job.allowance);
    // A table that moved across the write: verified at the next captured pose instead.
    if (!verification.value("pass", false) && !job.args.restore && station_) {
      const NoiseProfile* noise = station_->NoiseOf(static_cast<int>(device));
      const MeasurementModel* model = station_->ModelOf(sample.device, job.args.model);
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
        writes.at_pose = DeviceWrites::PoseCheckT{job.args.model, job.version,   job.theta,
                                                  job.covariance, std::string(), job.entry};
      }
    }
    job.entry["verification"] = verification;
    FinishDeviceWrite(sample.device, nullptr);
  }
}

void Service::StartStoredWrite(const std::string& name) {
  std::shared_ptr<DeviceWriteJob> job = writes_[name].job;
  std::size_t index = devices_.size();
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    if (devices_[i]->spec().name == name) index = i;
  }
  if (index == devices_.size()) {
    job->entry["state"] = "unchanged";
    job->entry["ok"] = false;
    job->entry["error"] = "nothing was written: " + name + " is no longer configured";
    FinishDeviceWrite(name, nullptr);
    return;
  }
  LiveDevice& device = *devices_[index];
  job->phase = DeviceWriteJob::Phase::kWriting;
  job->phase_started_ns = drivers::MonotonicNowNs();
  std::string error;
  // Before anything is written: what the write puts in, so that a turncald stopped mid-write
  // knows at the device's next dialogue what it holds (OnDeviceIdentity).
  {
    DeviceWrites& writes = writes_[name];
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
    if (!WriteDeviceWriteRecord(options_.state_dir, pending, &error)) {
      job->entry["state"] = "unchanged";
      job->entry["ok"] = false;
      job->entry["error"] = "nothing was written: " + error;
      FinishDeviceWrite(name, nullptr);
      return;
    }
    writes.record = pending;
  }
  const bool started = device.RunStoredWrite(
      job->steps, job->save,
      [this, name, job](const drivers::mip::StoredWriteOutcome& outcome,
                        const nlohmann::json& identity, const std::string& configure_error) {
        for (const auto& line : outcome.log) spdlog::info("{}: {}", name, line);
        job->entry["state"] = drivers::mip::ToString(outcome.state);
        job->entry["ok"] = outcome.ok();
        job->entry["error"] = outcome.error;
        job->entry["rollback_error"] = outcome.rollback_error;
        job->entry["log"] = outcome.log;
        job->entry["identity_after"] = identity;
        job->entry["configure_error"] = configure_error;
        if (const auto now = StoredCalibrationFromIdentity(identity)) {
          job->entry["device_holds"] = drivers::mip::StoredCalibrationJson(*now);
        }
        if (!outcome.ok()) {
          // What the device holds now (the dialogue after the write read it back) is in effect:
          // the old values after a rollback, or whatever a failed rollback left.
          DeviceWrites& writes = writes_[name];
          const auto now = StoredCalibrationFromIdentity(identity);
          // Without what the device holds now (the dialogue after the write failed too), the
          // record keeps `pending`: the next dialogue compares.
          if (writes.record && now) {
            DeviceWriteRecord record = *writes.record;
            record.pending.reset();
            record.in_device = *now;
            std::string record_error;
            if (!WriteDeviceWriteRecord(options_.state_dir, record, &record_error)) {
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
          FinishDeviceWrite(name, nullptr);
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
        const bool was_changed = writes_[name].record && writes_[name].record->nonvolatile_changed;
        record.nonvolatile_changed =
            job->args.restore ? (job->save ? false : was_changed) : (was_changed || job->save);
        std::string record_error;
        if (!WriteDeviceWriteRecord(options_.state_dir, record, &record_error)) {
          job->entry["record_error"] = record_error;
          spdlog::error("{}: {}", name, record_error);
        }
        DeviceWrites& writes = writes_[name];
        writes.record = record;
        writes.reexpress = record.reexpress();
        if (!configure_error.empty()) {
          job->entry["verification"] = {
              {"pass", false},
              {"summary", "not verified: the dialogue after the write failed (" + configure_error +
                              "); the device is retried, and device_writes/" + name +
                              ".json says what it holds"}};
          FinishDeviceWrite(name, nullptr);
          return;
        }
        job->phase = DeviceWriteJob::Phase::kAfter;
        job->phase_started_ns = drivers::MonotonicNowNs();
      },
      &error);
  if (!started) {
    job->entry["state"] = "unchanged";
    job->entry["ok"] = false;
    job->entry["error"] = error;
    FinishDeviceWrite(name, nullptr);
  }
}

}  // namespace turncal::daemon
