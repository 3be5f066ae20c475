#include "daemon/station.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <limits>
#include <mutex>

#include "core/pose_planner.h"
#include "daemon/persistence.h"
#include "drivers/transport/transport.h"
#include "protocol/calibration_json.h"
#include "protocol/observability_json.h"
#include "protocol/sequencer_json.h"
#include "turncal/version.h"

namespace turncal::daemon {

struct Station::ModelState {
  std::unique_ptr<MeasurementModel> model;
  std::unique_ptr<Calibrator> calibrator;
  Estimate estimate;
  // How many of the device's poses (poses_used, records_used) `estimate` saw: later poses may be
  // captured while its solve runs, and a calibration carries only its own evidence.
  std::size_t estimate_poses = 0;
  GateResult gate;
  int rank = 0;
  int active_version = 0;  // 0: no active calibration
  Estimate active;
  // The calibration live samples are corrected with: the active one, or the one stored in the
  // state directory when the station started (version 0 / empty: none).
  int applied_version = 0;
  Eigen::VectorXd applied_theta;
  Eigen::MatrixXd applied_covariance;  // empty when unknown
  // With a drift model: when the applied bias held, and how the bias wanders since (the
  // corrected output's sigma grows with the time since).
  std::optional<TimeWindow> applied_bias_window;
  BiasDrift applied_drift;
  // The correction as y = A raw + c, when the model's correction is affine in the raw sample (all
  // four models are: checked numerically when the calibration is applied). Live samples are
  // corrected with it, without the model's per-sample matrix solves.
  bool applied_affine = false;
  Eigen::Matrix3d applied_A = Eigen::Matrix3d::Identity();
  Eigen::Vector3d applied_c = Eigen::Vector3d::Zero();

  void Apply(int version, const Eigen::VectorXd& theta, const Eigen::MatrixXd& covariance,
             const std::optional<TimeWindow>& bias_window, const BiasDrift& drift) {
    applied_version = version;
    applied_theta = theta;
    applied_covariance = covariance;
    applied_bias_window = bias_window;
    applied_drift = drift;
    applied_c = model->Correct(theta, Eigen::Vector3d::Zero());
    for (int i = 0; i < 3; ++i) {
      applied_A.col(i) = model->Correct(theta, Eigen::Vector3d::Unit(i)) - applied_c;
    }
    // Affine when a point away from the probes maps the same both ways.
    const Eigen::Vector3d probe(0.83, -1.37, 2.11);
    const Eigen::Vector3d exact = model->Correct(theta, probe);
    const Eigen::Vector3d affine = applied_A * probe + applied_c;
    applied_affine = exact.allFinite() && (exact - affine).norm() <= 1e-12 * (1.0 + exact.norm());
  }
  // The calibrator is solved on the service's worker thread; this guards it.
  std::unique_ptr<std::mutex> calibrator_mutex = std::make_unique<std::mutex>();
};

struct Station::DeviceState {
  std::string name;
  std::unique_ptr<Sequencer> sequencer;
  std::vector<ModelState> models;
  std::vector<TablePose> poses_used;
  std::vector<PoseRecord> records_used;  // the same poses' records (a calibration's evidence)
  int poses = 0;
  bool noise_stored = false;  // the sequencer uses the profile kept in the state directory
  GateOptions gate;           // the station's, or the device's own
  nlohmann::json identity;    // from the device dialogue (null in replays)
  nlohmann::json current;     // the pose being collected: its last sequencer event
  // reports/NAME.html is rewritten after an activation, at most every kReportIntervalNs (the
  // render re-solves the calibration pose by pose: tens of ms on the worker).
  bool report_due = false;
  std::int64_t report_written_ns = std::numeric_limits<std::int64_t>::min() / 2;
};

namespace {

// The drift's identified strength, with the scale the solve used ("used": 1 while the poses do
// not reject the prior).
nlohmann::json DriftScaleJson(const Estimate& e) {
  nlohmann::json j = protocol::ToJson(e.drift_scale);
  j["used"] = e.drift_scale_used;
  return j;
}

// {NAME:{"value","sigma"}} in the model's order; sigma null when undetermined.
nlohmann::json ParamsJson(const Estimate& e) {
  nlohmann::json params = nlohmann::json::object();
  // A refused solve (too few poses) names its parameters but has no values yet.
  if (e.theta.size() != static_cast<Eigen::Index>(e.parameters.size()) ||
      e.sigma.size() != e.theta.size()) {
    return params;
  }
  for (std::size_t i = 0; i < e.parameters.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    params[e.parameters[i].name] = {
        {"value", e.theta[k]},
        {"sigma", std::isfinite(e.sigma[k]) ? nlohmann::json(e.sigma[k]) : nlohmann::json()}};
  }
  return params;
}

}  // namespace

bool StationOptions::IsValid(std::string* error) const {
  if (!sequencer.IsValid(error) || !gate.IsValid(error) || !table.IsValid(error)) return false;
  SensorClass c;
  if (!SensorClassByName(sensor_class, &c)) {
    if (error) *error = "unknown sensor class '" + sensor_class + "' (industrial, consumer)";
    return false;
  }
  if (models.empty()) {
    if (error) *error = "no model to estimate";
    return false;
  }
  for (const auto& m : models) {
    if (!MakeModel(m, context, error)) return false;
  }
  for (const auto& [name, own] : per_device) {
    if (own.models && own.models->empty()) {
      if (error) *error = "device '" + name + "': no model to estimate";
      return false;
    }
    for (const auto& m : own.models.value_or(std::vector<std::string>{})) {
      if (!MakeModel(m, context, error)) return false;
    }
    if (own.gate && !own.gate->IsValid(error)) return false;
  }
  return true;
}

Station::Station(std::vector<std::string> device_names, const StationOptions& options,
                 EventSink sink)
    : options_(options), sink_(std::move(sink)) {
  SensorClassByName(options_.sensor_class, &sensor_);
  if (options_.bias_tau_s > 0) sensor_.bias_tau_s = options_.bias_tau_s;
  if (options_.warmup_in_instabilities >= 0) {
    sensor_.warmup_in_instabilities = options_.warmup_in_instabilities;
  }
  if (options_.warmup_tau_s > 0) sensor_.warmup_tau_s = options_.warmup_tau_s;
  if (options_.acc_noise_density > 0) sensor_.acc_noise_density = options_.acc_noise_density;
  if (options_.acc_bias_instability > 0)
    sensor_.acc_bias_instability = options_.acc_bias_instability;
  if (options_.mag_noise_rms > 0) sensor_.mag_noise_rms = options_.mag_noise_rms;
  if (options_.mag_bias_instability > 0)
    sensor_.mag_bias_instability = options_.mag_bias_instability;
  if (!options_.gate_tolerances_set) {
    GateDefaultsForClass(options_.sensor_class, &options_.gate);
  }
  for (std::size_t i = 0; i < device_names.size(); ++i) {
    auto d = std::make_unique<DeviceState>();
    d->name = device_names[i];
    SequencerOptions so = options_.sequencer;
    // A still dwell's halves may differ by the sensor's own bias wander, not only by its white
    // noise: the class's Gauss-Markov drift, scaled by what the calibrator identifies (Apply).
    for (int t : {kTriadAcc, kTriadMag}) {
      BiasDrift& wander = so.stillness.bias_drift[static_cast<std::size_t>(t)];
      if (wander.enabled()) continue;
      wander.gm_sigma = Eigen::Vector3d::Constant(t == kTriadAcc ? sensor_.acc_bias_instability
                                                                 : sensor_.mag_bias_instability);
      wander.gm_tau_s = sensor_.bias_tau_s;
      wander.rw_density = Eigen::Vector3d::Constant(
          std::max(0.0, t == kTriadAcc ? options_.acc_random_walk : options_.mag_random_walk));
    }
    // The noise this session measured before a restart: stillness is judged as before.
    NoiseProfile stored;
    if (!so.noise && !options_.state_dir.empty() &&
        ReadNoiseProfile(options_.state_dir, d->name, &stored)) {
      so.noise = stored;
      d->noise_stored = true;
    }
    d->sequencer = std::make_unique<Sequencer>(
        so, [this, i](const SequencerEvent& e) { OnSequencerEvent(i, e); });
    d->gate = options_.gate;
    std::vector<std::string> models = options_.models;
    if (auto it = options_.per_device.find(d->name); it != options_.per_device.end()) {
      if (it->second.models) models = *it->second.models;
      if (it->second.gate) d->gate = *it->second.gate;
    }
    for (const auto& name : models) {
      ModelState m;
      std::string error;
      m.model = MakeModel(name, options_.context, &error);
      CalibratorOptions co = options_.drift_model ? DriftOptionsForClass(*m.model, sensor_)
                                                  : OptionsForClass(*m.model, sensor_);
      // The class's drift (or the one configured) is the prior; the session's poses identify
      // its strength.
      co.identify_drift = options_.drift_model && options_.identify_drift;
      if (options_.drift_model) {
        const double rw = m.model->sensor() == SensorKind::kAccelerometer
                              ? options_.acc_random_walk
                              : options_.mag_random_walk;
        if (rw > 0) co.drift.rw_density = Eigen::Vector3d::Constant(rw);
      }
      m.calibrator = std::make_unique<Calibrator>(co);
      d->models.push_back(std::move(m));
    }
    devices_.push_back(std::move(d));
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
    for (ModelState& m : d->models) {
      nlohmann::json stored;
      if (!ReadActiveCalibration(options_.state_dir, d->name, m.model->name(), &stored)) continue;
      const auto& params = m.model->parameters();
      Eigen::VectorXd theta(static_cast<Eigen::Index>(params.size()));
      bool ok = stored.contains("version") && stored["version"].is_number_integer() &&
                stored.contains("params") && stored["params"].is_object();
      for (std::size_t i = 0; ok && i < params.size(); ++i) {
        const auto it = stored["params"].find(params[i].name);
        ok = it != stored["params"].end() && it->is_object() && (*it)["value"].is_number();
        if (ok) theta[static_cast<Eigen::Index>(i)] = (*it)["value"].get<double>();
      }
      if (!ok) {
        Publish({{"class", "ERROR"},
                 {"device", d->name},
                 {"model", m.model->name()},
                 {"message", "the stored calibration is unreadable and is not applied"}});
        continue;
      }
      std::optional<TimeWindow> window;
      TimeWindow w;
      if (stored.contains("bias_window") && protocol::ParseTimeWindow(stored["bias_window"], &w)) {
        window = w;
      }
      BiasDrift drift;
      if (stored.contains("calibrator") && stored["calibrator"].is_object() &&
          stored["calibrator"].contains("drift")) {
        protocol::ParseBiasDrift(stored["calibrator"]["drift"], &drift);
      }
      m.Apply(stored["version"].get<int>(), theta, Eigen::MatrixXd(), window, drift);
      const auto& cov = stored.value("covariance", nlohmann::json());
      if (cov.is_array() && cov.size() == params.size()) {
        Eigen::MatrixXd c(theta.size(), theta.size());
        bool good = true;
        for (std::size_t r = 0; good && r < params.size(); ++r) {
          good = cov[r].is_array() && cov[r].size() == params.size();
          for (std::size_t k = 0; good && k < params.size(); ++k) {
            good = cov[r][k].is_number();
            if (good) {
              c(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(k)) =
                  cov[r][k].get<double>();
            }
          }
        }
        if (good) m.applied_covariance = c;
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

void Station::SetDeviceIdentity(int device, nlohmann::json identity) {
  devices_[static_cast<std::size_t>(device)]->identity = std::move(identity);
}

bool Station::HasAppliedCalibration(int device) const {
  for (const ModelState& m : devices_[static_cast<std::size_t>(device)]->models) {
    if (m.applied_version > 0) return true;
  }
  return false;
}

namespace {

// 1 sigma per axis of model.Correct(theta, raw) from cov(theta): J cov J^T with J by central
// differences (steps of 1e-6 of each parameter's scale); nullopt without a usable covariance.
// `bias_drift_var`, per axis, is added to the bias parameters' variance: how far the bias may
// have wandered since the calibration.
std::optional<Eigen::Vector3d> CorrectionSigma(const MeasurementModel& model,
                                               const Eigen::VectorXd& theta,
                                               Eigen::MatrixXd covariance,
                                               const Eigen::Vector3d& raw,
                                               const Eigen::Vector3d& bias_drift_var) {
  const Eigen::Index n = theta.size();
  if (covariance.rows() != n || covariance.cols() != n || !covariance.allFinite()) {
    return std::nullopt;
  }
  const auto& params = model.parameters();
  for (Eigen::Index k = 0; k < n; ++k) {
    const std::string& name = params[static_cast<std::size_t>(k)].name;
    if (name == "bx" || name == "by" || name == "bz")
      covariance(k, k) += bias_drift_var[name[1] - 'x'];
  }
  Jacobian3 jacobian(3, n);
  Eigen::VectorXd t = theta;
  for (Eigen::Index k = 0; k < n; ++k) {
    const double h = 1e-6 * std::max(1.0, std::abs(theta[k]));
    t[k] = theta[k] + h;
    const Eigen::Vector3d up = model.Correct(t, raw);
    t[k] = theta[k] - h;
    const Eigen::Vector3d down = model.Correct(t, raw);
    t[k] = theta[k];
    jacobian.col(k) = (up - down) / (2 * h);
  }
  const Eigen::Matrix3d c = jacobian * covariance * jacobian.transpose();
  return c.diagonal().cwiseMax(0.0).cwiseSqrt();
}

}  // namespace

bool Station::Correct(int device, const Sample& sample, Corrected* out, bool with_sigma) const {
  *out = Corrected{};
  for (const ModelState& m : devices_[static_cast<std::size_t>(device)]->models) {
    if (m.applied_version <= 0) continue;
    const bool accel = m.model->sensor() == SensorKind::kAccelerometer;
    const std::optional<Eigen::Vector3d>& raw = accel ? sample.acc_mps2 : sample.mag;
    if (!raw) continue;
    std::optional<Eigen::Vector3d>& target = accel ? out->acc_mps2 : out->mag;
    if (target) continue;  // the first model of a sensor in the configured order wins
    target = m.applied_affine ? Eigen::Vector3d(m.applied_A * *raw + m.applied_c)
                              : m.model->Correct(m.applied_theta, *raw);
    if (with_sigma) {
      Eigen::Vector3d drift_var = Eigen::Vector3d::Zero();
      if (m.applied_bias_window && m.applied_drift.enabled()) {
        const double t_s = static_cast<double>(sample.t_host_ns) * 1e-9;
        const TimeWindow& w = *m.applied_bias_window;
        // A clock before the calibration's (the host restarted since): the time since is
        // unknown, so the wander's long-term limit (infinite for a random walk).
        const double since_s = t_s >= w.t0_s ? t_s : w.t1_s + 1e9;
        for (int axis = 0; axis < 3; ++axis) {
          drift_var[axis] = m.applied_drift.VarianceSince(axis, w, since_s);
        }
      }
      (accel ? out->acc_sigma : out->mag_sigma) =
          CorrectionSigma(*m.model, m.applied_theta, m.applied_covariance, *raw, drift_var);
    }
    (accel ? out->acc_frame : out->mag_frame) = ToString(m.model->corrected_frame());
    out->versions.emplace_back(m.model->name(), m.applied_version);
  }
  return !out->versions.empty();
}

nlohmann::json Station::Status(int device) const {
  const DeviceState& d = *devices_[static_cast<std::size_t>(device)];
  nlohmann::json models = nlohmann::json::object();
  for (const ModelState& m : d.models) {
    const CalibratorOptions& co = m.calibrator->options();
    models[m.model->name()] = {
        {"poses", m.estimate.poses},
        {"gate", ToJson(m.gate)},
        {"fit_check", ToString(m.estimate.fit.verdict)},
        {"noise_model", co.drift.enabled()
                            ? protocol::ToJson(m.estimate.ok ? m.estimate.drift : co.drift)
                            : nlohmann::json{{"pose_offset_sigma", co.pose_offset_sigma}}},
        {"drift_scale",
         m.estimate.ok && co.identify_drift ? DriftScaleJson(m.estimate) : nlohmann::json()},
        {"active_version", m.active_version},
        {"applied_version", m.applied_version}};
  }
  const SampleCounts& t = d.sequencer->totals();
  return {{"poses", d.poses},
          {"captured", d.sequencer->captured()},
          {"rejected", d.sequencer->rejected()},
          {"busy", d.sequencer->busy()},
          {"noise", d.sequencer->noise() ? "measured" : "measuring"},
          {"noise_profile",
           d.sequencer->noise() ? protocol::ToJson(*d.sequencer->noise()) : nlohmann::json()},
          {"current", d.sequencer->busy() ? d.current : nlohmann::json()},
          {"samples",
           {{"used", t.used}, {"flagged", t.flagged}, {"outliers", t.outliers}, {"lost", t.lost}}},
          {"models", models}};
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

nlohmann::json Station::CalibrationJson(const DeviceState& d, const ModelState& m) const {
  const Estimate& e = m.estimate;
  nlohmann::json order = nlohmann::json::array();
  for (const auto& p : e.parameters) order.push_back(p.name);
  nlohmann::json covariance = nlohmann::json::array();
  for (Eigen::Index r = 0; r < e.covariance.rows(); ++r) {
    nlohmann::json row = nlohmann::json::array();
    for (Eigen::Index c = 0; c < e.covariance.cols(); ++c) {
      const double v = e.covariance(r, c);
      row.push_back(std::isfinite(v) ? nlohmann::json(v) : nlohmann::json());
    }
    covariance.push_back(row);
  }
  const std::size_t n = std::min(m.estimate_poses, d.poses_used.size());
  nlohmann::json poses = nlohmann::json::array();
  for (std::size_t i = 0; i < n; ++i) poses.push_back(ToJson(d.poses_used[i]));
  // The records themselves, with the model's triad only, so that the calibration can be
  // re-evaluated (the report's residuals and convergence) without the journal, which `reset`
  // archives.
  const bool accel = m.model->sensor() == SensorKind::kAccelerometer;
  nlohmann::json records = nlohmann::json::array();
  for (std::size_t i = 0; i < n && i < d.records_used.size(); ++i) {
    PoseRecord r = d.records_used[i];
    r.gyr.reset();
    (accel ? r.mag : r.acc).reset();
    records.push_back(protocol::ToJson(r));
  }
  nlohmann::json calibrator =
      protocol::CalibratorJson(m.calibrator->options(), options_.sensor_class);
  if (e.drift.enabled()) {
    // The drift the solve used (the prior times the identified scale): corrected output's sigma
    // grows with it, also after a restart; the configured one stays as the prior.
    calibrator["drift_prior"] = calibrator["drift"];
    calibrator["drift"] = protocol::ToJson(e.drift);
    calibrator["drift_scale"] = DriftScaleJson(e);
  }
  // Device identity and the device-side stored calibration come from the device dialogue of a
  // live station (SetDeviceIdentity); a replay does not have them (null).
  const nlohmann::json provenance = {
      {"poses", poses}, {"records", records}, {"device_identity", d.identity}};
  return {{"schema", 1},
          {"class", "CALIBRATION"},
          {"device", d.name},
          {"model", m.model->name()},
          {"version", m.active_version},
          {"software", kVersion},
          {"time", drivers::UtcNowIso8601()},
          {"params", ParamsJson(e)},
          {"parameter_order", order},
          {"covariance", covariance},
          {"gauge", e.gauge},
          {"bias_window", e.bias_window ? protocol::ToJson(*e.bias_window) : nlohmann::json()},
          {"rank", m.rank},
          {"chi2", e.chi2},
          {"dof", e.dof},
          {"p_value", e.p_value},
          {"fit_check", protocol::ToJson(e.fit, m.model->sensor())},
          {"gate", ToJson(m.gate)},
          {"tolerances", protocol::TolerancesJson(*m.model, d.gate)},
          {"context", protocol::ToJson(options_.context)},
          {"calibrator", calibrator},
          {"provenance", provenance}};
}

// What one model's update computes (on the solve worker when there is one).
struct Station::UpdateJob {
  std::size_t device_poses = 0;  // the device's poses when the update was queued, this one included
  bool added = false;
  std::string error;
  Estimate estimate;
  int rank = 0;
  GateResult gate;
};

void Station::Update(std::size_t device, const PoseRecord& record, double t_s) {
  DeviceState& d = *devices_[device];
  ++d.poses;
  d.poses_used.push_back(record.pose);
  d.records_used.push_back(record);
  for (std::size_t mi = 0; mi < d.models.size(); ++mi) {
    ModelState& m = d.models[mi];
    const bool accel = m.model->sensor() == SensorKind::kAccelerometer;
    if (accel ? !record.acc : !record.mag) continue;
    auto job = std::make_shared<UpdateJob>();
    job->device_poses = d.records_used.size();
    // The calibrator is only touched under its lock (the worker solves; NextPose reads).
    auto work = [&m, record, job, gate = d.gate] {
      std::lock_guard lock(*m.calibrator_mutex);
      job->added = m.calibrator->add_pose(record, &job->error);
      if (!job->added) return;
      job->estimate = m.calibrator->solve();
      if (job->estimate.ok) {
        const DataReport data = AnalyzeData(*m.model, job->estimate.theta,
                                            m.calibrator->weighted_poses(), ObservabilityOptions{});
        job->rank = data.analysis.rank;
        job->gate = EvaluateGate(*m.model, job->estimate, data, gate);
      } else {
        job->gate.reasons.push_back("no estimate: " + job->estimate.error);
      }
    };
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
  const int triad = m.model->sensor() == SensorKind::kAccelerometer ? kTriadAcc : kTriadMag;
  const NoiseProfile* before = d.sequencer->noise();
  const auto& stored = before ? before->identified_drift[static_cast<std::size_t>(triad)]
                              : std::optional<IdentifiedDrift>();
  const bool moved =
      !stored || std::abs(std::log(m.estimate.drift_scale_used / stored->scale)) > 0.01;
  d.sequencer->SetIdentifiedDrift(
      triad, IdentifiedDrift{m.estimate.drift, m.estimate.drift_scale_used, m.estimate.poses});
  const NoiseProfile* noise = d.sequencer->noise();
  if (!moved || options_.state_dir.empty() || noise == nullptr) return;
  auto error = std::make_shared<std::string>();
  Defer([dir = options_.state_dir, name = d.name, profile = *noise,
         error] { WriteNoiseProfile(dir, name, profile, error.get()); },
        [this, name = d.name, error] { NoteWrite(name, *error); });
}

void Station::Apply(std::size_t device, std::size_t model, double t_s, const UpdateJob& job,
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
  m.estimate = job.estimate;
  m.estimate_poses = job.device_poses;
  if (m.estimate.ok && m.calibrator->options().identify_drift) RecordIdentifiedDrift(device, m);
  m.rank = job.rank;
  m.gate = job.gate;
  if (sink_ && !resuming) {
    // Every gated parameter's sigma against its tolerance (the watch view's bars).
    nlohmann::json precision = nlohmann::json::object();
    if (m.estimate.ok && m.estimate.sigma.size() == m.model->num_parameters()) {
      const auto& params = m.model->parameters();
      for (int j : GatedParameters(*m.model)) {
        const double sigma = m.estimate.sigma[j];
        precision[params[static_cast<std::size_t>(j)].name] = {
            {"sigma", std::isfinite(sigma) ? nlohmann::json(sigma) : nlohmann::json()},
            {"tolerance", ToleranceFor(params[static_cast<std::size_t>(j)], d.gate)}};
      }
    }
    sink_({{"class", "ESTIMATE"},
           {"t", t_s},
           {"device", d.name},
           {"model", m.model->name()},
           {"poses", m.estimate.poses},
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
  nlohmann::json calibration = CalibrationJson(d, m);
  if (!override_who.is_null()) calibration["override"] = override_who;
  nlohmann::json event = {{"class", "CALIBRATION_ACTIVE"},
                          {"t", t_s},
                          {"device", d.name},
                          {"model", m.model->name()},
                          {"version", m.active_version},
                          {"poses", m.estimate.poses}};
  if (!override_who.is_null()) event["override"] = override_who;
  // Persisted (atomically, fsynced: off the loop), then applied and announced.
  auto write_error = std::make_shared<std::string>();
  Defer(
      [dir = options_.state_dir, device = d.name, model = m.model->name(), calibration,
       write_error] {
        if (!dir.empty())
          WriteActiveCalibration(dir, device, model, calibration, write_error.get());
      },
      [this, &d, &m, event, write_error, version = m.active_version, theta = m.estimate.theta,
       covariance = m.estimate.covariance, window = m.estimate.bias_window,
       drift = m.estimate.drift] {
        if (!options_.state_dir.empty()) NoteWrite(d.name, *write_error);
        if (version > m.applied_version) m.Apply(version, theta, covariance, window, drift);
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

bool Station::PublishOverride(const std::string& device, const std::string& model,
                              const nlohmann::json& who, std::string* error) {
  const int i = DeviceIndex(device);
  if (i < 0) {
    *error = "no device '" + device + "'";
    return false;
  }
  DeviceState& d = *devices_[static_cast<std::size_t>(i)];
  for (ModelState& m : d.models) {
    if (m.model->name() != model) continue;
    if (!m.estimate.ok) {
      *error = fmt::format("{} {} has no estimate to publish{}", device, model,
                           m.estimate.error.empty() ? "" : ": " + m.estimate.error);
      return false;
    }
    nlohmann::json record = who;
    record["gate_pass"] = m.gate.pass;
    record["gate_reasons"] = m.gate.reasons;
    Activate(d, m, 0.0, record);
    return true;
  }
  *error = fmt::format("device '{}' estimates no model '{}'", device, model);
  return false;
}

nlohmann::json Station::NextPose(const std::string& device) const {
  const int i = DeviceIndex(device);
  if (i < 0)
    return {{"class", "NEXT_POSE"}, {"ok", false}, {"error", "no device '" + device + "'"}};
  const DeviceState& d = *devices_[static_cast<std::size_t>(i)];
  std::vector<PlanningTarget> targets;
  for (const ModelState& m : d.models) {
    // The drift model and the poses' times: a new pose is weighed by what it adds given every
    // earlier one at the time the table would reach it (core/pose_planner.h).
    // A new pose's white noise from the device's own noise profile when it has one.
    const NoiseProfile* noise = d.sequencer->noise();
    const int triad = m.model->sensor() == SensorKind::kAccelerometer ? kTriadAcc : kTriadMag;
    std::lock_guard lock(*m.calibrator_mutex);  // a solve in progress finishes first
    targets.push_back(
        TargetFromCalibrator(*m.calibrator, m.estimate.ok ? m.estimate.theta : m.model->nominal(),
                             options_.sequencer.dwell_s, d.gate,
                             noise ? noise->sigma[static_cast<std::size_t>(triad)] : std::nullopt,
                             noise ? noise->rate_hz : 0.0));
  }
  PlannerOptions planner;
  planner.motion = options_.table;
  planner.objective = options_.plan_objective;
  planner.dwell_s = options_.sequencer.dwell_s;
  nlohmann::json j = ToJson(PlanNextPose(targets, planner));
  j["device"] = device;
  return j;
}

nlohmann::json Station::Result() const {
  nlohmann::json devices = nlohmann::json::object();
  for (const auto& d : devices_) {
    nlohmann::json models = nlohmann::json::object();
    for (const ModelState& m : d->models) {
      const Estimate& e = m.estimate;
      models[m.model->name()] = {
          {"ok", e.ok},
          {"poses", e.poses},
          {"params", ParamsJson(e)},
          {"rank", m.rank},
          {"chi2", e.chi2},
          {"dof", e.dof},
          {"p_value", e.p_value},
          {"fit_check", protocol::ToJson(e.fit, m.model->sensor())},
          {"drift_scale",
           e.ok && m.calibrator->options().identify_drift ? DriftScaleJson(e) : nlohmann::json()},
          {"bias_window", e.bias_window ? protocol::ToJson(*e.bias_window) : nlohmann::json()},
          {"gauge", e.gauge},
          {"warnings", e.warnings},
          {"gate", ToJson(m.gate)},
          {"active_version", m.active_version}};
    }
    devices[d->name] = {{"poses", d->poses},
                        {"samples",
                         {{"used", d->sequencer->totals().used},
                          {"flagged", d->sequencer->totals().flagged},
                          {"outliers", d->sequencer->totals().outliers},
                          {"lost", d->sequencer->totals().lost}}},
                        {"captured", d->sequencer->captured()},
                        {"rejected", d->sequencer->rejected()},
                        {"models", models}};
  }
  return {{"class", "RESULT"}, {"devices", devices}};
}

}  // namespace turncal::daemon
