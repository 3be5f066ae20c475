// The device_write request (docs/protocol.md "Writing a calibration into the device"): a
// device's active calibration into its stored calibration, or (restore) what it held before
// turncal wrote into it. The plan first (daemon/device_write/device_write_plan.h), shown to the
// client; then, unless it is a dry run or refused, the write begins with a window of the device's
// output (daemon/device_write/device_writer_job.cc).
#include "daemon/device_write/device_writer.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "daemon/device/live_device.h"
#include "daemon/device_write/device_write_plan.h"
#include "daemon/state/persistence.h"
#include "daemon/station/model_pipeline.h"
#include "drivers/mip/mip_stored.h"
#include "drivers/transport/transport.h"
#include "protocol/calibration_json.h"
#include "protocol/free_json.h"

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

// The request's calibration: the correction a pose model's or a free model's document describes
// (issue 22: accel9, gyro9, gyro9g, magellipsoid, magsphere), its values and covariance. The free
// model, when it is one, lives in *free_model as long as the request does. False with a message.
bool CorrectionOfDocument(const nlohmann::json& calibration, const std::string& device,
                          const std::string& model_name, const DeviceWriter::Hooks& hooks,
                          DeviceWriteRequest* q, std::unique_ptr<FreeModel>* free_model,
                          std::string* error) {
  std::string why;
  if (protocol::IsFreeCalibration(calibration)) {
    protocol::FreeCalibrationDocument doc;
    if (!protocol::ParseFreeCalibration(calibration, &doc, &why)) {
      *error = "the active calibration of " + model_name + ": " + why;
      return false;
    }
    if (doc.model == "accmag") {
      *error =
          "accmag calibrates two triads and the rotation between them: write accel9 and "
          "magellipsoid (or magsphere) instead";
      return false;
    }
    *free_model = MakeFreeModel(doc.model, doc.context, &why);
    if (!*free_model) {
      *error = why;
      return false;
    }
    const FreeModel& m = **free_model;
    const double scale =
        m.sensor() == SensorKind::kAccelerometer ? doc.context.gravity_mps2
        : m.sensor() == SensorKind::kMagnetometer && doc.context.field_magnitude > 0
            ? doc.context.field_magnitude
            : 1.0;
    q->correction = CorrectionOf(m, scale);
    q->theta = doc.theta;
    q->covariance = doc.covariance;
    return true;
  }
  const MeasurementModel* model = hooks.model_of(device, model_name);
  if (!model) {
    *error = fmt::format("{} has no model '{}' in this station", device, model_name);
    return false;
  }
  q->model = model;
  if (!protocol::ReadCalibrationValues(*model, calibration, &q->theta, &q->covariance)) {
    *error = "the active calibration's document lacks a parameter of " + model_name;
    return false;
  }
  return true;
}

}  // namespace

DeviceWriter::DeviceWriter(Hooks hooks) : hooks_(std::move(hooks)) {}

DeviceWriter::~DeviceWriter() = default;

void DeviceWriter::Configure(std::string state_dir, StationOptions station) {
  state_dir_ = std::move(state_dir);
  station_ = std::move(station);
}

const DeviceWriteRecord* DeviceWriter::record(const std::string& device) const {
  const auto it = writes_.find(device);
  return it == writes_.end() || !it->second.record ? nullptr : &*it->second.record;
}

bool DeviceWriter::writing(const std::string& device) const {
  const auto it = writes_.find(device);
  return it != writes_.end() && it->second.job != nullptr;
}

bool DeviceWriter::verification_pending(const std::string& device) const {
  const auto it = writes_.find(device);
  return it != writes_.end() && it->second.at_pose.has_value();
}

void DeviceWriter::Request(const protocol::DeviceWriteArgs& args, int uid, Reply reply) {
  const auto fail = [&](const std::string& message, const nlohmann::json& plan = nullptr) {
    nlohmann::json e = protocol::ErrorMessage("device_write: " + message);
    if (!plan.is_null()) e["plan"] = plan;
    reply(e);
  };
  if (state_dir_.empty()) {
    fail("turncald has no state directory, and the values a write replaces must be kept there");
    return;
  }
  WritableDevice* device = hooks_.device(args.device);
  if (!device) {
    fail("no device '" + args.device + "'");
    return;
  }
  Writes& writes = writes_[args.device];
  if (writes.job) {
    fail("a write into " + args.device + " is under way");
    return;
  }
  const nlohmann::json identity = device->identity();
  const std::optional<StoredCalibration> actual = StoredCalibrationFromIdentity(identity);
  // What the station's calibrations see the output in.
  const StoredCalibration as_if_now =
      writes.reexpress ? writes.record->as_if : actual.value_or(StoredCalibration{});

  auto job = std::make_shared<Job>();
  job->reply = reply;
  job->args = args;
  job->serial = identity.is_object() ? identity.value("serial", "") : "";
  std::vector<std::string> refusals;
  std::string error;
  if (args.restore ? !PlanRestore(actual, &writes, job.get(), &refusals, &error)
                   : !PlanWrite(*device, actual, as_if_now, job.get(), &refusals, &error)) {
    fail(error);
    return;
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
  if (device->state() != "streaming") {
    fail(fmt::format("{} is {}, not streaming", args.device, device->state()));
    return;
  }
  const double rate_hz = identity.is_object() && identity.value("rate_hz", 0.0) > 0
                             ? identity.value("rate_hz", 0.0)
                             : DefaultRateHz(device->spec().protocol);
  job->window = std::clamp(static_cast<int>(std::lround(rate_hz * kWindowSeconds)), 20, 1000);
  job->phase_started_ns = hooks_.now_ns();
  job->entry = {{"schema", 1},
                {"class", "DEVICE_WRITE"},
                {"device", args.device},
                {"operation", args.restore ? "restore" : "write"},
                {"model", args.model},
                {"version", job->version},
                {"serial", job->serial},
                {"save", job->save},
                {"time", drivers::UtcNowIso8601()},
                {"uid", uid},
                {"plan", job->plan}};
  writes.job = job;
  spdlog::info("{}: {} {} v{} requested by uid {}: averaging {} samples of the output first",
               args.device, args.restore ? "restore" : "write", args.model, job->version, uid,
               job->window);
}

bool DeviceWriter::PlanWrite(const WritableDevice& device,
                             const std::optional<StoredCalibration>& actual,
                             const StoredCalibration& as_if_now, Job* job,
                             std::vector<std::string>* refusals, std::string* error) {
  const protocol::DeviceWriteArgs& args = job->args;
  nlohmann::json calibration;
  if (!ReadActiveCalibration(state_dir_, args.device, args.model, &calibration)) {
    *error = fmt::format(
        "{} has no active calibration of {} (one that passed its gate, or was published)",
        args.device, args.model);
    return false;
  }
  DeviceWriteRequest q;
  q.device = args.device;
  q.protocol = device.spec().protocol;
  q.serial_now = job->serial;
  q.stored_now = as_if_now;
  q.transform = args.transform;
  std::unique_ptr<FreeModel> free_model;  // lives until the plan is made
  if (!CorrectionOfDocument(calibration, args.device, args.model, hooks_, &q, &free_model, error)) {
    return false;
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
    refusals->push_back(args.device + " has not told turncald what it stores (state " +
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
    *refusals = plan.refusals;
  }
  job->plan["operation"] = "write";
  if (args.version && *args.version != q.version) {
    refusals->push_back(
        fmt::format("the plan shown was for version {}; version {} is active now: look at it again",
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
  return true;
}

bool DeviceWriter::PlanRestore(const std::optional<StoredCalibration>& actual, Writes* writes,
                               Job* job, std::vector<std::string>* refusals, std::string* error) {
  const protocol::DeviceWriteArgs& args = job->args;
  if (!writes->record) {
    bool exists = false;
    DeviceWriteRecord record;
    if (!ReadDeviceWriteRecord(state_dir_, args.device, &record, &exists, error)) return false;
    if (exists) writes->record = record;
  }
  if (!writes->record) {
    *error = "nothing to restore: no write into " + args.device + " is recorded in " + state_dir_ +
             "/device_writes";
    return false;
  }
  const DeviceWriteRecord& r = *writes->record;
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
  if (!actual) refusals->push_back(args.device + " has not told its stored calibration yet");
  if (actual && !SameStoredCalibration(*actual, r.in_device)) {
    refusals->push_back(args.device +
                        " holds other values than the last write left: nothing is restored "
                        "(device_writes/" +
                        args.device + ".json has what was written)");
  }
  if (!job->serial.empty() && job->serial != r.serial) {
    refusals->push_back(fmt::format("the record is of serial {}; {} is serial {}", r.serial,
                                    args.device, job->serial));
  }
  if (job->steps.empty() && refusals->empty()) {
    refusals->push_back(args.device +
                        " already holds the values its calibrations were made "
                        "with: nothing to restore");
  }
  job->plan = {{"device", args.device},
               {"operation", "restore"},
               {"serial", job->serial},
               {"restores_write", {{"model", r.model}, {"version", r.version}, {"time", r.time}}},
               {"writes", list},
               {"save", job->save},
               {"ok", refusals->empty()},
               {"refusals", *refusals}};
  return true;
}

}  // namespace turncal::daemon
