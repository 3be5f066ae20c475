#include "daemon/station/station.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <limits>
#include <mutex>

#include "core/planning/pose_planner.h"
#include "daemon/state/persistence.h"
#include "drivers/transport/transport.h"
#include "protocol/calibration_json.h"
#include "protocol/observability_json.h"
#include "protocol/sequencer_json.h"
#include "turncal/version.h"

namespace turncal::daemon {

Station::Station(std::vector<std::string> device_names, const StationOptions& options,
                 EventSink sink)
    : options_(options), sink_(std::move(sink)) {
  sensor_ = options_.ResolvedSensorClass();
  if (!options_.gate_tolerances_set) {
    GateDefaultsForClass(options_.sensor_class, &options_.gate);
  }
  for (std::size_t i = 0; i < device_names.size(); ++i) {
    auto d = std::make_unique<DeviceState>();
    d->name = device_names[i];
    SequencerOptions so = DevicePipeline::SequencerOptionsFor(options_, sensor_);
    // The noise this session measured before a restart: stillness is judged as before.
    NoiseProfile stored;
    if (!so.noise && !options_.state_dir.empty() &&
        ReadNoiseProfile(options_.state_dir, d->name, &stored)) {
      so.noise = stored;
      d->noise_stored = true;
    }
    d->gate = options_.gate;
    std::vector<std::string> models = options_.models;
    // The device's pose models in its own mount's context (issue 38).
    StationOptions device_options = options_;
    if (auto it = options_.per_device.find(d->name); it != options_.per_device.end()) {
      if (it->second.models) models = *it->second.models;
      if (it->second.gate) d->gate = *it->second.gate;
      if (it->second.mount) {
        device_options.context.mounting = *it->second.mount;
        d->mount_configured = true;
      }
      d->slot = it->second.slot;
    }
    d->context = device_options.context;
    d->calibrations = MakeCalibrationSet(models, device_options, sensor_, d->gate);
    // The moves between poses are a gyroscope model's evidence: tracked only for one.
    so.moves.enabled = so.moves.enabled && d->calibrations->NeedsMoves();
    d->sequencer = std::make_unique<Sequencer>(
        so, [this, i](const SequencerEvent& e) { OnSequencerEvent(i, e); });
    devices_.push_back(std::move(d));
    // After the device is in place (a free set announces the first interval it waits for).
    devices_.back()->calibrations->Start(*devices_.back()->sequencer);
  }
  OpenSessionBatch();
  if (!options_.state_dir.empty()) {
    LoadApplied();
    Resume();
  }
  PublishBatchIfChanged();
}

// The session's batch: the state directory's (a resumed session keeps its id), else a new one.
void Station::OpenSessionBatch() {
  if (options_.state_dir.empty()) {
    batch_ = NewBatch(options_.batch_id, options_.fixture);
  } else {
    std::string note, error;
    if (!OpenBatch(options_.state_dir, options_.batch_id, options_.fixture, &batch_, &note,
                   &error)) {
      NoteWrite("", "the batch file: " + error);
    }
    if (!note.empty()) Publish({{"class", "ERROR"}, {"message", note}});
  }
}

void Station::PublishBatchIfChanged() {
  if (resuming_) return;
  nlohmann::json b = BatchStatus();
  // Changed: a unit's state, why or poses (not the link, which `status` adds).
  nlohmann::json key = nlohmann::json::array();
  for (const auto& u : b["units"]) key.push_back({u["state"], u.value("why", ""), u["poses"]});
  if (key == batch_published_) return;
  batch_published_ = key;
  if (!options_.state_dir.empty()) {
    // batch.json with the units' states: the report's batch summary reads it.
    auto error = std::make_shared<std::string>();
    DeferWrite([dir = options_.state_dir, b, error] { WriteBatchStatus(dir, b, error.get()); },
               [this, error] { NoteWrite("", *error); });
  }
  b["class"] = "BATCH";
  Publish(b);
}

// The calibrations stored in the state directory are applied to live samples from the start:
// a restarted daemon corrects with what it published before.
void Station::LoadApplied() {
  for (auto& d : devices_) {
    for (const auto& name : d->calibrations->StoredNames()) {
      nlohmann::json stored;
      if (!ReadActiveCalibration(options_.state_dir, d->name, name, &stored)) continue;
      std::string error;
      if (!d->calibrations->Restore(name).ApplyStored(stored, &error)) {
        Publish({{"class", "ERROR"},
                 {"device", d->name},
                 {"model", name},
                 {"message", "the stored calibration is unreadable and is not applied" +
                                 (error.empty() ? std::string() : ": " + error)}});
      }
    }
  }
}

int Station::DeviceIndex(const std::string& name) const {
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    if (devices_[i]->name == name) return static_cast<int>(i);
  }
  return -1;
}

const NoiseProfile* Station::NoiseOf(int device) const {
  return devices_[static_cast<std::size_t>(device)]->sequencer->noise();
}

std::optional<double> Station::SensorTimeOf(int device, const Sample& sample) const {
  if (!sample.t_device_s || !std::isfinite(*sample.t_device_s)) return std::nullopt;
  return devices_[static_cast<std::size_t>(device)]->sequencer->SensorTimeOfDevice(
      *sample.t_device_s);
}

const MeasurementModel* Station::ModelOf(const std::string& device,
                                         const std::string& model) const {
  const int i = DeviceIndex(device);
  if (i < 0) return nullptr;
  const Calibration* c = devices_[static_cast<std::size_t>(i)]->calibrations->Find(model);
  return c ? c->writable_model() : nullptr;
}

void Station::SetDeviceIdentity(int device, nlohmann::json identity) {
  DeviceState& d = *devices_[static_cast<std::size_t>(device)];
  d.identity = std::move(identity);
  // Two units of the batch with one serial (issue 38): one cable in two ports, or a unit whose
  // serial was cloned. Their calibrations would be filed under one unit (certificate, registry):
  // the later one to report is named and its calibrations held until the conflict is gone (a
  // device answering with another serial clears it).
  const std::string serial = d.Serial();
  std::string other;
  for (const auto& o : devices_) {
    if (o.get() != &d && !serial.empty() && o->Serial() == serial &&
        o->duplicate_serial_of.empty()) {
      other = o->name;
      break;
    }
  }
  if (other == d.duplicate_serial_of) return;
  d.duplicate_serial_of = other;
  if (other.empty()) {
    PublishBatchIfChanged();
    return;
  }
  Publish({{"class", "ERROR"},
           {"device", d.name},
           {"message", fmt::format("{} reports serial {}, as {} does: two units with one serial "
                                   "(one unit on two ports, or a cloned serial). {}'s "
                                   "calibrations are held until it reports a serial of its own",
                                   d.name, serial, other, d.name)}});
  PublishBatchIfChanged();
}

Station::~Station() { *alive_ = false; }

void Station::SetExecutor(Executor executor) { executor_ = std::move(executor); }

void Station::Publish(const nlohmann::json& event) {
  if (sink_) sink_(event);
}

// A journal from an earlier run of this session: its poses go through the calibrators again
// (without re-journaling or re-publishing), and versions continue from the stored calibrations.
void Station::Resume() {
  std::vector<JournalEntry> entries;
  int skipped = 0;
  std::string error;
  if (!PoseJournal::Load(options_.state_dir, &entries, &skipped, &error)) {
    Publish({{"class", "ERROR"}, {"message", error}});
  }
  resuming_ = true;
  std::vector<int> resumed(devices_.size(), 0);
  for (const auto& e : entries) {
    for (std::size_t i = 0; i < devices_.size(); ++i) {
      if (devices_[i]->name != e.device) continue;
      if (e.is_motion()) {
        devices_[i]->calibrations->OnMotionValues(*devices_[i], e.motion);
        continue;
      }
      Update(i, e.record, e.record.t_end_s);
      ++resumed[i];
    }
  }
  for (auto& d : devices_) d->calibrations->OnResumed(*d, *this);
  resuming_ = false;
  for (auto& d : devices_) {
    if (d->mount_check.wrong) PublishMount(*d);
  }
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    Publish({{"class", "SESSION_RESUMED"},
             {"device", devices_[i]->name},
             {"poses", resumed[i]},
             {"noise", devices_[i]->noise_stored ? "stored" : "to be measured"},
             {"journal_lines_skipped", skipped}});
  }
  journal_wanted_ = true;
  EnsureJournal();
}

bool Station::EnsureJournal() {
  if (journal_ || !journal_wanted_) return journal_ != nullptr;
  std::string error;
  journal_ = std::make_shared<PoseJournal>();
  if (!journal_->Open(options_.state_dir, &error)) {
    journal_.reset();
    NoteWrite("", error + "; captured poses are not saved until it can be opened");
    return false;
  }
  return true;
}

void Station::NoteWrite(const std::string& device, const std::string& error) {
  if (error.empty()) {
    ++writes_ok_;
    write_error_.clear();
    return;
  }
  ++writes_failed_;
  write_error_ = error;
  nlohmann::json e = {{"class", "ERROR"}, {"message", error}};
  if (!device.empty()) e["device"] = device;
  Publish(e);
}

nlohmann::json Station::PersistenceStatus() const {
  return {{"state_dir", options_.state_dir},
          {"journal_open", journal_ != nullptr},
          {"writes", writes_ok_},
          {"failed_writes", writes_failed_},
          {"last_error", write_error_}};
}

void Station::OnSample(int device, const Sample& sample) {
  DeviceState& d = *devices_[static_cast<std::size_t>(device)];
  d.sequencer->Push(sample);
  d.calibrations->OnSample(d, sample, *this);
  if (static_cast<std::size_t>(device) < rest_noise_.size() &&
      rest_noise_[static_cast<std::size_t>(device)]) {
    AddRestNoise(device, sample);
  }
}

void Station::JournalMotion(DeviceState& d, std::vector<MotionValue> values) {
  if (values.empty() || !EnsureJournal()) return;
  auto error = std::make_shared<std::string>();
  DeferWrite([journal = journal_, name = d.name, values = std::move(values),
              error] { journal->AppendMotion(name, values, error.get()); },
             [this, name = d.name, error] {
               NoteWrite(name, *error);
               if (!error->empty()) journal_.reset();  // reopened before the next append
             });
}

void Station::TickDevice(int device, std::int64_t now_ns) {
  DeviceState& d = *devices_[static_cast<std::size_t>(device)];
  d.sequencer->Tick(now_ns);
  // A live device whose latest pose is kIdleSolveS old: what its calibrations deferred (a fit
  // over temperature thins its refits) is solved now, so the session's last poses count without
  // waiting for another.
  if (!d.records_used.empty() &&
      1e-9 * static_cast<double>(now_ns) - d.records_used.back().t_end_s > kIdleSolveS) {
    d.calibrations->OnIdle(d, *this);
  }
  WriteReport(static_cast<std::size_t>(device), now_ns, false);
}

void Station::WriteDueReports() {
  for (std::size_t i = 0; i < devices_.size(); ++i) WriteReport(i, 0, true);
}

void Station::WriteReport(std::size_t device, std::int64_t now_ns, bool now) {
  DeviceState& d = *devices_[device];
  if (!d.report_due || options_.state_dir.empty()) return;
  if (!now && now_ns - d.report_written_ns < kReportIntervalNs) return;
  d.report_due = false;
  d.report_written_ns = now_ns;
  std::vector<std::string> models;
  for (std::size_t i = 0; i < d.calibrations->size(); ++i) {
    const Calibration& c = d.calibrations->at(i);
    if (c.active_version() > 0) models.push_back(c.name());
  }
  auto error = std::make_shared<std::string>();
  DeferWrite(
      [dir = options_.state_dir, name = d.name, models, error] {
        WriteDeviceReport(dir, name, models, drivers::UtcNowIso8601(), error.get());
      },
      [this, name = d.name, error] {
        if (!error->empty()) Publish({{"class", "ERROR"}, {"device", name}, {"message", *error}});
      });
}

void Station::SetChamber(std::optional<double> setpoint_c) {
  chamber_setpoint_c_ = setpoint_c;
  for (auto& d : devices_) {
    if (!setpoint_c) {
      d->sequencer->SetSoak(std::nullopt);
      continue;
    }
    SoakOptions soak = options_.thermal.soak;
    soak.setpoint_c = *setpoint_c;
    d->sequencer->SetSoak(soak);
  }
}

bool Station::AnnounceTo(int device, const Announcement& a, std::string* error) {
  return devices_[static_cast<std::size_t>(device)]->sequencer->Announce(a, error);
}

bool Station::OnAnnounce(const Announcement& a, const std::vector<int>& devices,
                         std::string* error) {
  bool ok = true;
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    if (AnnouncedTo(devices, static_cast<int>(i))) {
      ok = devices_[i]->sequencer->Announce(a, error) && ok;
      if (i < rest_noise_.size() && rest_noise_[i]) NoteRestNoiseMove(i);
    }
  }
  return ok;
}

void Station::OnTick(std::int64_t now_ns) {
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    devices_[i]->sequencer->Tick(now_ns);
    WriteReport(i, now_ns, false);
  }
}

void Station::OnFinish(std::int64_t now_ns) {
  for (auto& d : devices_) d->sequencer->Finish(now_ns);
  for (auto& d : devices_) d->calibrations->OnFinish(*d, *this);
  WriteDueReports();
}

namespace {
double ThreadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}
}  // namespace

void Station::OnSequencerEvent(std::size_t device, const SequencerEvent& e) {
  const bool captured = e.kind == SequencerEventKind::kCaptured && e.record;
  const double cpu0_ms = captured ? ThreadCpuMs() : 0.0;
  HandleSequencerEvent(device, e);
  if (captured) {
    capture_cpu_ms_last_ = ThreadCpuMs() - cpu0_ms;
    capture_cpu_ms_max_ = std::max(capture_cpu_ms_max_, capture_cpu_ms_last_);
  }
}

void Station::HandleSequencerEvent(std::size_t device, const SequencerEvent& e) {
  // A captured pose is answered once its record is in the journal (below): a controller that
  // moves the table on POSE_CAPTURED must not lose the pose to a crash right after.
  const bool capture = e.kind == SequencerEventKind::kCaptured && e.record;
  const bool journaled_answer = capture && EnsureJournal();
  if ((sink_ && !journaled_answer) || e.kind == SequencerEventKind::kPoseStarted ||
      e.kind == SequencerEventKind::kCollecting || e.kind == SequencerEventKind::kProgress) {
    nlohmann::json j = protocol::ToJson(e);
    j["device"] = devices_[device]->name;
    if (e.kind == SequencerEventKind::kPoseStarted || e.kind == SequencerEventKind::kCollecting ||
        e.kind == SequencerEventKind::kProgress) {
      devices_[device]->current = j;
    }
    if (capture) {
      j["saved"] = false;
      j["save_error"] = options_.state_dir.empty()
                            ? "turncald runs without a state directory"
                            : "the journal cannot be opened: " + write_error_;
    }
    if (sink_) sink_(j);
  }
  devices_[device]->calibrations->OnSequencerEvent(e);
  if (e.kind == SequencerEventKind::kNoiseMeasured && !options_.state_dir.empty() &&
      devices_[device]->sequencer->noise()) {
    auto error = std::make_shared<std::string>();
    const std::string name = devices_[device]->name;
    DeferWrite([dir = options_.state_dir, name, noise = *devices_[device]->sequencer->noise(),
                error] { WriteNoiseProfile(dir, name, noise, error.get()); },
               [this, name, error] { NoteWrite(name, *error); });
  }
  if (e.kind == SequencerEventKind::kCaptured && e.record) {
    // Journaled (fsynced) before it is used: the worker runs in order, so the append precedes the
    // update; a crash after the append loses nothing.
    if (journal_) {
      auto error = std::make_shared<std::string>();
      const std::string name = devices_[device]->name;
      nlohmann::json answer = protocol::ToJson(e);
      answer["device"] = name;
      DeferWrite([journal = journal_, name, record = *e.record,
                  error] { journal->Append(name, record, error.get()); },
                 [this, name, error, answer = std::move(answer)]() mutable {
                   NoteWrite(name, *error);
                   // Claimed saved only when the record is in the journal (fsynced).
                   answer["saved"] = error->empty();
                   if (!error->empty()) {
                     answer["save_error"] = *error;
                     // An append that failed may have left a partial line: reopen before the next.
                     journal_.reset();
                   }
                   Publish(answer);
                 });
    }
    Update(device, *e.record, e.t_s);
  }
}

void Station::Update(std::size_t device, const PoseRecord& record, double t_s) {
  DeviceState& d = *devices_[device];
  ++d.poses;
  if (!(record.t_start_s >= batch_t0_s_)) batch_t0_s_ = record.t_start_s;  // NaN: the first
  d.poses_used.push_back(record.pose);
  d.records_used.push_back(record);
  // Does the unit sit as its mount says? Checked before its calibrations learn from the pose, so
  // that a wrong slot holds their activation from the pose that shows it.
  if (options_.pose_source == PoseSource::kAnnounced && d.CheckMountWith(record) &&
      d.mount_check.wrong && !resuming_) {
    PublishMount(d);
  }
  d.calibrations->OnRecord(d, record, t_s, resuming_, *this);
  PublishBatchIfChanged();
}

void Station::PublishMount(DeviceState& d) {
  if (d.mount_wrong_published) return;
  d.mount_wrong_published = true;
  nlohmann::json e = {{"class", "MOUNT"}, {"device", d.name}, {"message", d.MountProblem()}};
  e.update(d.MountJson());
  Publish(e);
  PublishBatchIfChanged();
}

void Station::SaveNoiseProfile(DeviceState& d) {
  const NoiseProfile* noise = d.sequencer->noise();
  if (options_.state_dir.empty() || noise == nullptr) return;
  auto error = std::make_shared<std::string>();
  DeferWrite([dir = options_.state_dir, name = d.name, profile = *noise,
              error] { WriteNoiseProfile(dir, name, profile, error.get()); },
             [this, name = d.name, error] { NoteWrite(name, *error); });
}

void Station::Activate(DeviceState& d, Calibration& c, double t_s,
                       const nlohmann::json& override_who) {
  if (!d.duplicate_serial_of.empty() && override_who.is_null()) {
    // Held: another unit of the batch reported the same serial (SetDeviceIdentity said so).
    return;
  }
  if (d.mount_check.wrong && override_who.is_null()) {
    // A unit that does not sit as configured: its calibration is held, not activated (its
    // mounting angles would carry the wrong slot's rotation). Said once per verdict.
    PublishMount(d);
    return;
  }
  Activation a = c.Activate(d, ActivationContext{options_.sensor_class, d.context}, t_s);
  if (!override_who.is_null()) {
    a.document["override"] = override_who;
    a.event["override"] = override_who;
  }
  // The batch it belongs to (issue 38): the registry, the report and the certificate read it.
  nlohmann::json batch = batch_.Json();
  batch["slot"] = d.slot.empty() ? nlohmann::json() : nlohmann::json(d.slot);
  batch["units"] = devices_.size();
  batch["seconds"] = std::isfinite(batch_t0_s_) && t_s > 0.0 ? nlohmann::json(t_s - batch_t0_s_)
                                                             : nlohmann::json();
  a.document["batch"] = batch;
  a.event["batch"] = batch_.id;
  if (override_who.is_null() && !std::isfinite(d.passed_t_s) && t_s > 0.0) {
    bool all = true;
    for (std::size_t i = 0; i < d.calibrations->size(); ++i) {
      const Calibration& k = d.calibrations->at(i);
      all = all && k.GatePassed() && (&k == &c || k.active_version() > 0);
    }
    if (all) d.passed_t_s = t_s;
  }
  // Persisted (atomically, fsynced: off the loop), then applied and announced.
  auto write_error = std::make_shared<std::string>();
  DeferWrite(
      [dir = options_.state_dir, device = d.name, model = c.name(),
       calibration = std::move(a.document), write_error, saved = options_.on_calibration_saved] {
        if (dir.empty()) return;
        if (WriteActiveCalibration(dir, device, model, calibration, write_error.get()) && saved) {
          saved(calibration);
        }
      },
      [this, &d, event = std::move(a.event), write_error, apply = std::move(a.apply)] {
        if (!options_.state_dir.empty()) NoteWrite(d.name, *write_error);
        apply();
        if (write_error->empty()) d.report_due = true;  // TickDevice/OnTick write it
        // Claimed saved only when calibrations/DEVICE/MODEL.json holds it (renamed, fsynced).
        nlohmann::json announced = event;
        announced["saved"] = !options_.state_dir.empty() && write_error->empty();
        if (!write_error->empty()) announced["save_error"] = *write_error;
        Publish(announced);
        PublishBatchIfChanged();
      });
}

void Station::Abandon() { *abandoned_ = true; }

void Station::Defer(std::function<void()> work, std::function<void()> done) {
  DeferWrite(
      [abandoned = abandoned_, skipped = skipped_, work = std::move(work)] {
        if (*abandoned) {
          ++*skipped;
          return;
        }
        work();
      },
      std::move(done));
}

void Station::DeferWrite(std::function<void()> work, std::function<void()> done) {
  auto guarded = [alive = alive_, done = std::move(done)] {
    if (*alive) done();
  };
  if (executor_ && !resuming_) {
    executor_(std::move(work), std::move(guarded));
  } else {
    work();
    guarded();
  }
}

}  // namespace turncal::daemon
