#include "daemon/station/station.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <limits>
#include <mutex>

#include "core/planning/pose_planner.h"
#include "daemon/state/persistence.h"
#include "drivers/transport/transport.h"
#include "protocol/calibration_json.h"
#include "protocol/free_json.h"
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
    if (auto it = options_.per_device.find(d->name); it != options_.per_device.end()) {
      if (it->second.models) models = *it->second.models;
      if (it->second.gate) d->gate = *it->second.gate;
    }
    bool gyro = false;
    if (free_mode()) {
      d->free = std::make_unique<FreeDevice>();
      d->free->configured = models;
      d->free->context = FreeContextFor(options_, sensor_);
      d->free->options = FreeOptionsFor(options_, d->gate);
      // What the data carry may include a gyroscope: its moves are then its evidence.
      gyro = models.empty();
      std::string error;
      for (const auto& name : models) {
        auto model = MakeFreeModel(name, d->free->context, &error);
        gyro = gyro || (model && model->Needs(SensorKind::kGyroscope));
        d->free->Get(name);
      }
    } else {
      for (const auto& name : models) {
        d->models.push_back(ModelPipeline::Make(name, options_, sensor_));
        const auto& model = d->models.back().model;
        gyro = gyro || (model && model->sensor() == SensorKind::kGyroscope);
      }
    }
    // The moves between poses are a gyroscope model's evidence: tracked only for one.
    so.moves.enabled = so.moves.enabled && gyro;
    d->sequencer = std::make_unique<Sequencer>(
        so, [this, i](const SequencerEvent& e) { OnSequencerEvent(i, e); });
    devices_.push_back(std::move(d));
    // After the device is in place: SetFree announces the first interval it waits for.
    if (devices_.back()->free) {
      std::string error;
      devices_.back()->sequencer->SetFree(&error);  // a new sequencer is idle, unscheduled
    }
  }
  if (!options_.state_dir.empty()) {
    LoadApplied();
    Resume();
  }
}

// The calibrations stored in the state directory are applied to live samples from the start:
// a restarted daemon corrects with what it published before.
void Station::LoadApplied() {
  for (auto& d : devices_) {
    if (d->free) {
      // Every free model stored for the device (with models from the data, any of them).
      const std::vector<std::string> names =
          d->free->configured.empty() ? FreeModelNames() : d->free->configured;
      for (const auto& name : names) {
        nlohmann::json stored;
        if (!ReadActiveCalibration(options_.state_dir, d->name, name, &stored)) continue;
        std::string error;
        FreeModelState& m = d->free->Get(name);
        if (!m.ApplyStored(stored, &error)) {
          Publish(
              {{"class", "ERROR"},
               {"device", d->name},
               {"model", name},
               {"message", "the stored calibration is unreadable and is not applied: " + error}});
          continue;
        }
        m.active_version = m.applied_version;
      }
      continue;
    }
    for (ModelState& m : d->models) {
      nlohmann::json stored;
      if (!ReadActiveCalibration(options_.state_dir, d->name, m.model->name(), &stored)) continue;
      if (!m.ApplyStored(stored)) {
        Publish({{"class", "ERROR"},
                 {"device", d->name},
                 {"model", m.model->name()},
                 {"message", "the stored calibration is unreadable and is not applied"}});
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

const MeasurementModel* Station::ModelOf(const std::string& device,
                                         const std::string& model) const {
  const int i = DeviceIndex(device);
  if (i < 0) return nullptr;
  for (const ModelState& m : devices_[static_cast<std::size_t>(i)]->models) {
    if (m.model->name() == model) return m.model.get();
  }
  return nullptr;
}

void Station::SetDeviceIdentity(int device, nlohmann::json identity) {
  devices_[static_cast<std::size_t>(device)]->identity = std::move(identity);
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
  for (auto& d : devices_) {
    for (ModelState& m : d->models) {
      nlohmann::json stored;
      if (ReadActiveCalibration(options_.state_dir, d->name, m.model->name(), &stored) &&
          stored.contains("version") && stored["version"].is_number_integer()) {
        m.active_version = stored["version"].get<int>();
      }
    }
  }
  resuming_ = true;
  std::vector<int> resumed(devices_.size(), 0);
  for (const auto& e : entries) {
    for (std::size_t i = 0; i < devices_.size(); ++i) {
      if (devices_[i]->name != e.device) continue;
      Update(i, e.record, e.record.t_end_s);
      ++resumed[i];
    }
  }
  // A free device's resumed intervals are fitted once, all together.
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    DeviceState& d = *devices_[i];
    if (d.free && d.free->refit_due) {
      d.free->refit_due = false;
      QueueFreeFit(i, d.records_used.empty() ? 0.0 : d.records_used.back().t_end_s);
    }
  }
  resuming_ = false;
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
  devices_[static_cast<std::size_t>(device)]->sequencer->Push(sample);
}

void Station::TickDevice(int device, std::int64_t now_ns) {
  devices_[static_cast<std::size_t>(device)]->sequencer->Tick(now_ns);
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
  for (const auto& m : d.models) {
    if (m.active_version > 0) models.push_back(m.model->name());
  }
  if (d.free) {
    for (const auto& m : d.free->models) {
      if (m->active_version > 0) models.push_back(m->requested);
    }
  }
  auto error = std::make_shared<std::string>();
  Defer([dir = options_.state_dir, name = d.name, models,
         error] { WriteDeviceReport(dir, name, models, drivers::UtcNowIso8601(), error.get()); },
        [this, name = d.name, error] {
          if (!error->empty()) Publish({{"class", "ERROR"}, {"device", name}, {"message", *error}});
        });
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
  if (e.kind == SequencerEventKind::kSegmentSkipped && devices_[device]->free) {
    devices_[device]->free->NoteSkipped(fmt::format("at {:.2f} s: {}", e.t_s, e.reason));
  }
  if (e.kind == SequencerEventKind::kNoiseMeasured && !options_.state_dir.empty() &&
      devices_[device]->sequencer->noise()) {
    auto error = std::make_shared<std::string>();
    const std::string name = devices_[device]->name;
    Defer([dir = options_.state_dir, name, noise = *devices_[device]->sequencer->noise(),
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
      Defer([journal = journal_, name, record = *e.record,
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
  d.poses_used.push_back(record.pose);
  d.records_used.push_back(record);
  if (d.free) {
    if (resuming_) {
      d.free->refit_due = true;  // once, at the end of the resume
    } else {
      QueueFreeFit(device, t_s);
    }
    return;
  }
  for (std::size_t mi = 0; mi < d.models.size(); ++mi) {
    ModelState& m = d.models[mi];
    if (!m.TriadOf(record)) continue;  // e.g. a rate segment holds the gyro only
    auto job = std::make_shared<ModelUpdate>();
    job->device_poses = d.records_used.size();
    // The calibrator is only touched under its lock (the worker solves; NextPose reads).
    auto work = [&m, record, job, gate = d.gate] { m.AddAndSolve(record, gate, job.get()); };
    // The station may be replaced (reset, reload) before `done` runs: Defer guards it.
    Defer(std::move(work), [this, device, mi, t_s, job, resuming = resuming_] {
      Apply(device, mi, t_s, *job, resuming);
    });
  }
}

// The drift a calibrator identified goes to the device's noise profile: the sequencer's
// stillness tests allow for it, and noise/DEVICE.json keeps it (rewritten when the scale moves by
// more than 1 %, or the triad had none).
void Station::RecordIdentifiedDrift(std::size_t device, const ModelState& m) {
  DeviceState& d = *devices_[device];
  const bool moved = d.RecordIdentifiedDrift(m);
  const NoiseProfile* noise = d.sequencer->noise();
  if (!moved || options_.state_dir.empty() || noise == nullptr) return;
  auto error = std::make_shared<std::string>();
  Defer([dir = options_.state_dir, name = d.name, profile = *noise,
         error] { WriteNoiseProfile(dir, name, profile, error.get()); },
        [this, name = d.name, error] { NoteWrite(name, *error); });
}

void Station::Apply(std::size_t device, std::size_t model, double t_s, const ModelUpdate& job,
                    bool resuming) {
  DeviceState& d = *devices_[device];
  ModelState& m = d.models[model];
  if (!job.added) {
    if (sink_) {
      sink_({{"class", "ERROR"},
             {"device", d.name},
             {"model", m.model->name()},
             {"message", "pose not used: " + job.error}});
    }
    return;
  }
  m.moves_refused = job.moves_refused;
  m.last_move_refusal = job.last_move_refusal;
  m.estimate = job.estimate;
  m.estimate_poses = job.device_poses;
  if (m.estimate.ok && m.calibrator->options().identify_drift) RecordIdentifiedDrift(device, m);
  m.rank = job.rank;
  m.gate = job.gate;
  if (sink_ && !resuming) {
    // Every gated parameter's sigma against its tolerance (the watch view's bars).
    const nlohmann::json precision = m.PrecisionJson(d.gate);
    sink_({{"class", "ESTIMATE"},
           {"t", t_s},
           {"device", d.name},
           {"model", m.model->name()},
           {"poses", m.estimate.poses},
           {"moves", m.estimate.moves},
           {"summary", m.estimate.BriefReport()},
           {"precision", precision},
           {"gate", ToJson(m.gate)}});
  }
  if (m.gate.pass && !resuming) {
    Activate(d, m, t_s, nullptr);
  } else if (m.gate.pass) {
    m.active = m.estimate;
    m.Apply(m.active_version, m.estimate.theta, m.estimate.covariance, m.estimate.bias_window,
            m.estimate.drift);
  }
}

void Station::Activate(DeviceState& d, ModelState& m, double t_s,
                       const nlohmann::json& override_who) {
  ++m.active_version;
  m.active = m.estimate;
  nlohmann::json calibration = d.CalibrationJson(m, options_.sensor_class, options_.context);
  if (!override_who.is_null()) calibration["override"] = override_who;
  nlohmann::json event = {{"class", "CALIBRATION_ACTIVE"},
                          {"t", t_s},
                          {"device", d.name},
                          {"model", m.model->name()},
                          {"version", m.active_version},
                          {"poses", m.estimate.poses},
                          {"moves", m.estimate.moves}};
  if (!override_who.is_null()) event["override"] = override_who;
  PersistCalibration(
      d, m.model->name(), std::move(calibration), std::move(event),
      [&m, version = m.active_version, theta = m.estimate.theta, covariance = m.estimate.covariance,
       window = m.estimate.bias_window, drift = m.estimate.drift] {
        if (version > m.applied_version) m.Apply(version, theta, covariance, window, drift);
      });
}

void Station::PersistCalibration(DeviceState& d, const std::string& model,
                                 nlohmann::json calibration, nlohmann::json event,
                                 std::function<void()> apply) {
  // Persisted (atomically, fsynced: off the loop), then applied and announced.
  auto write_error = std::make_shared<std::string>();
  Defer(
      [dir = options_.state_dir, device = d.name, model, calibration = std::move(calibration),
       write_error, saved = options_.on_calibration_saved] {
        if (dir.empty()) return;
        if (WriteActiveCalibration(dir, device, model, calibration, write_error.get()) && saved) {
          saved(calibration);
        }
      },
      [this, &d, event = std::move(event), write_error, apply = std::move(apply)] {
        if (!options_.state_dir.empty()) NoteWrite(d.name, *write_error);
        apply();
        if (write_error->empty()) d.report_due = true;  // TickDevice/OnTick write it
        // Claimed saved only when calibrations/DEVICE/MODEL.json holds it (renamed, fsynced).
        nlohmann::json announced = event;
        announced["saved"] = !options_.state_dir.empty() && write_error->empty();
        if (!write_error->empty()) announced["save_error"] = *write_error;
        Publish(announced);
      });
}

void Station::Defer(std::function<void()> work, std::function<void()> done) {
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
