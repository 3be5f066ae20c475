#include "montecarlo/pipeline_montecarlo.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <thread>

#include "core/frames/mount.h"
#include "core/planning/pose_planner.h"
#include "core/sequencing/sequencer.h"
#include "daemon/state/persistence.h"
#include "daemon/station/replay_once.h"
#include "montecarlo/nominal_target.h"
#include "montecarlo/parallel_runs.h"
#include "montecarlo/pipeline_thermal.h"
#include "protocol/calibration_json.h"
#include "sim/capture.h"
#include "sim/fixture_capture.h"
#include "sim/session_sim.h"
#include "sim/synthetic.h"

namespace turncal::montecarlo {

namespace {

// The rates the planner may give a gyroscope's rate segments: sim/session_sim.h's defaults.
const std::vector<double> kPlannedRatesDps = {100.0, -100.0, 100.0 / 3, -100.0 / 3};

// The simulated table's rate accuracy: its ripple (1e-4 at 2 Hz, phase drawn per segment)
// averages to ~2e-6 of the rate over a revolution at 100 deg/s (1e-4 / (2 pi 2 Hz 3.6 s)). The
// station is told it, and the planner plans with it.
constexpr double kSimulatedRateAccuracy = 2e-6;

// A file or folder of one run, removed when the run ends.
struct RemovedOnExit {
  explicit RemovedOnExit(std::string p) : path(std::move(p)) {}
  ~RemovedOnExit() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
  RemovedOnExit(const RemovedOnExit&) = delete;
  RemovedOnExit& operator=(const RemovedOnExit&) = delete;
  std::string path;
};

// The engine: Run prepares what every run shares (the model, the class, the table, the plan),
// runs the sessions on `jobs` threads, each one Simulate -> Replay -> JudgedEstimate -> Truth ->
// Score, and summarises them.
class PipelineMonteCarlo {
 public:
  explicit PipelineMonteCarlo(const PipelineMonteCarloOptions& options) : o_(options) {}

  PipelineMonteCarloSummary Run() {
    PipelineMonteCarloSummary s;
    if (!Prepare(&s)) return s;
    const auto start = std::chrono::steady_clock::now();
    s.runs = RunAll();
    s.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    Summarise(&s);
    return s;
  }

 private:
  // The model, protocol and class the options name, the simulated table and the plan every run
  // follows; false with the summary's error when they cannot be had.
  bool Prepare(PipelineMonteCarloSummary* s) {
    protocol_ = drivers::ParseProtocol(o_.protocol);
    model_ = MakeModel(o_.model, ModelContext{}, &s->error);
    if (!protocol_ || !model_ || !SensorClassByName(o_.sensor_class, &sensor_)) {
      if (!protocol_) s->error = "unknown protocol '" + o_.protocol + "'";
      if (protocol_ && model_) s->error = "unknown class '" + o_.sensor_class + "'";
      s->bad_options = true;
      return false;
    }
    s->error.clear();
    accel_ = model_->sensor() == SensorKind::kAccelerometer;
    gyro_ = model_->sensor() == SensorKind::kGyroscope;
    s->gyro = gyro_;
    bias_ = model_->index_of("bx");
    station_model_ = o_.model;
    if (!o_.chamber.empty()) {
      if (!PrepareChamber(s)) return false;
    } else {
      for (const auto& p : model_->parameters()) s->parameters.push_back(p.name);
    }
    if (o_.table_rate_dps > 0) {
      table_.emplace();
      table_->rate_dps.setConstant(o_.table_rate_dps);
      table_->accel_dps2.setConstant(o_.table_accel_dps2);
      table_->settle_s = SessionSimOptions{}.settle_s;
    }
    plan_ = DefaultSessionPoses();
    if (o_.plan == "planner") {
      plan_ = PlannerSequence(&s->predicted_poses, &s->error);
      if (plan_.empty()) return false;
    }
    if (!(gyro_ && o_.plan == "planner")) plan_ = WithRateSegments(plan_);
    if (o_.units > 1 && (chamber_ || o_.units > 16)) {
      s->error = chamber_ ? "--units: a fixture is not simulated in a chamber"
                          : "--units: at most 16 units";
      s->bad_options = true;
      return false;
    }
    for (int u = 0; u < std::max(1, o_.units); ++u) {
      mounts_.emplace_back();
      ParseMountAxes(sim::kFixtureMounts[u % 4], &mounts_.back(), nullptr);
    }
    return true;
  }

  // In a chamber: the profile, the truth's orders, the temperatures judged and the names scored.
  bool PrepareChamber(PipelineMonteCarloSummary* s) {
    chamber_.emplace();
    if (!ChamberProfile::Parse(o_.chamber, &*chamber_, &s->error)) {
      s->error = "--chamber: " + s->error;
      s->bad_options = true;
      return false;
    }
    if (model_->gauge_dimension() > 0 ||
        (o_.thermal_orders != "chosen" && o_.thermal_orders != "truth")) {
      s->error = model_->gauge_dimension() > 0
                     ? o_.model + " has a gauge: not calibrated over temperature (use mag13)"
                     : "--thermal-orders must be truth or chosen with --pipeline";
      s->bad_options = true;
      return false;
    }
    station_model_ = o_.model + "@T";
    truth_basis_ = ThermalTruthBasis(*model_, sensor_, chamber_->middle_c());
    held_out_c_ = o_.held_out_c.empty() ? DefaultHeldOutTemperatures(*chamber_) : o_.held_out_c;
    s->parameters = ThermalScoredNames(
        *model_, o_.thermal_orders == "truth" ? &truth_basis_ : nullptr, held_out_c_);
    return true;
  }

  // The D-optimal planner's plan to the gate from nominal values, for the accelerometer and
  // magnetometer models a station calibrates together (what `turncal plan --model accel13
  // --model mag13` prints), or for a gyroscope model alone with the rate segments and moves its
  // sources allow (`turncal plan --model gyro12 [--rates ...] [--no-moves]`): the recommended
  // pose and its continuation, for the simulated table. Empty with *error when it cannot plan.
  std::vector<TablePose> PlannerSequence(int* predicted_poses, std::string* error) const {
    // A gyroscope's records are what the station captures: its sequencer's dwell (whole
    // revolutions of at least it for a rate segment) of the simulator's longer rest, the rest of
    // which lengthens each move (the station measures the same on the moves it captures).
    const double station_dwell_s = SequencerOptions{}.dwell_s;
    const double dwell_s = gyro_ ? std::min(o_.dwell_s, station_dwell_s) : o_.dwell_s;
    const std::vector<std::string> names =
        gyro_ ? std::vector<std::string>{o_.model} : std::vector<std::string>{"accel13", "mag13"};
    std::vector<std::unique_ptr<MeasurementModel>> models;
    std::vector<PlanningTarget> targets;
    for (const std::string& name : names) {
      auto model = MakeModel(name, ModelContext{}, error);
      if (!model) return {};
      targets.push_back(NominalPlanningTarget(*model, sensor_, o_.planner_drift != "independent",
                                              dwell_s, sim::SimDefaultRateHz(*protocol_)));
      if (gyro_) targets.back().rate_accuracy = kSimulatedRateAccuracy;
      models.push_back(std::move(model));
    }
    const NextPoseAdvice a = PlanNextPose(targets, PlannerOptionsFor(dwell_s, station_dwell_s));
    if (!a.ok) {
      *error = "the planner: " + a.error;
      return {};
    }
    *predicted_poses = a.poses_to_gate;
    return a.continuation;
  }

  PlannerOptions PlannerOptionsFor(double dwell_s, double station_dwell_s) const {
    PlannerOptions options;
    if (gyro_) {
      if (o_.gyro_sources != "moves") options.rates.rates_dps = kPlannedRatesDps;
      options.moves = o_.gyro_sources == "moves" || o_.gyro_sources == "all";
      options.move_rest_s = std::max(0.0, o_.dwell_s - station_dwell_s);
    }
    options.dwell_s = dwell_s;
    options.objective =
        o_.planner_objective == "poses" ? PlanObjective::kPoses : PlanObjective::kTime;
    if (table_) {
      options.motion = *table_;
    } else {
      // The simulator's fixed moves: every pose costs the same time, only the drift's timing
      // counts.
      options.motion.rate_dps.setConstant(1e6);
      options.motion.accel_dps2.setConstant(1e12);
      options.motion.settle_s = SessionSimOptions{}.move_s + SessionSimOptions{}.settle_s;
    }
    // A whole session's plan, as long as the default one, so that the gate's first pass is the
    // station's and the estimate at the end is judged after as many poses as the other plans.
    options.min_continuation = static_cast<int>(DefaultSessionPoses().size());
    return options;
  }

  // A gyroscope's rate segments in the static plan (not the planner's: it placed those its
  // sources allow): after the static poses ("all"), interleaved after each of the first ones
  // ("mixed"), or alone ("rates"); "moves" and the other triads' models keep the static poses.
  std::vector<TablePose> WithRateSegments(const std::vector<TablePose>& plan) const {
    if (!gyro_ || o_.gyro_sources == "moves") return plan;
    const std::vector<TablePose> rates = DefaultRateSegments();
    if (o_.gyro_sources == "all") {
      std::vector<TablePose> all = plan;
      all.insert(all.end(), rates.begin(), rates.end());
      return all;
    }
    std::vector<TablePose> mixed;
    const std::vector<TablePose> statics =
        o_.gyro_sources == "rates" ? std::vector<TablePose>{} : plan;
    for (std::size_t i = 0; i < std::max(statics.size(), rates.size()); ++i) {
      if (i < statics.size()) mixed.push_back(statics[i]);
      if (i < rates.size()) mixed.push_back(rates[i]);
    }
    return mixed;
  }

  // Every run, `jobs` at a time, in a scratch folder removed at the end; a fixture's runs give
  // one PipelineRun per unit, in order.
  std::vector<PipelineRun> RunAll() {
    if (o_.units <= 1) {
      return RunInScratchDir<PipelineRun>("turncal-montecarlo", o_.runs, o_.jobs, &dir_,
                                          [this](int run, PipelineRun* out) { RunOne(run, out); });
    }
    const auto sessions = RunInScratchDir<std::vector<PipelineRun>>(
        "turncal-montecarlo", o_.runs, o_.jobs, &dir_,
        [this](int run, std::vector<PipelineRun>* out) { RunFixture(run, out); });
    std::vector<PipelineRun> runs;
    for (const auto& units : sessions) runs.insert(runs.end(), units.begin(), units.end());
    return runs;
  }

  // One fixture's session: `units` units simulated in their mounts, merged into one capture,
  // replayed through one station, each unit's estimate scored against its own truth.
  void RunFixture(int run, std::vector<PipelineRun>* out) {
    const std::uint64_t base = o_.seed * 1000003 + static_cast<std::uint64_t>(run);
    out->assign(static_cast<std::size_t>(o_.units), PipelineRun{});
    std::vector<sim::SimCapture> units(out->size());
    std::string error;
    for (std::size_t u = 0; u < units.size() && error.empty(); ++u) {
      (*out)[u].seed = base * 16 + u;
      (*out)[u].unit = static_cast<int>(u);
      sim::SimCaptureOptions o = SimulationFor((*out)[u].seed);
      o.mount = mounts_[u];
      sim::BuildSimCapture(o, &units[u], &error);
    }
    sim::SimCapture fixture;
    const RemovedOnExit path((dir_ / fmt::format("run-{}.tcap", run)).string());
    const RemovedOnExit state_dir((dir_ / fmt::format("state-{}", run)).string());
    daemon::ReplayOnceOutcome replay;
    PipelineRun events;  // the replay's error and the rejections, of any unit
    if (error.empty() && sim::MergeFixtureCaptures(units, &fixture, &error) &&
        sim::WriteSimCapture(fixture, path.path, &error)) {
      Replay(path.path, state_dir.path, static_cast<double>(fixture.offset_ns) * 1e-9, &replay,
             &events, out);
      error = events.error;
    }
    for (std::size_t u = 0; u < units.size(); ++u) {
      PipelineRun& r = (*out)[u];
      r.error = error;
      if (!error.empty()) continue;
      const double offset_s = static_cast<double>(fixture.offset_ns) * 1e-9;
      nlohmann::json m;
      Eigen::VectorXd truth;
      if (!JudgedEstimate(&replay.result, state_dir.path, fmt::format("imu{}", u + 1), &m,
                          &r.error) ||
          !Truth(units[u], m, offset_s, &truth, &r.error)) {
        continue;
      }
      Score(m, truth, &r);
      r.rejected = events.rejected;
      r.session_s = units[u].session.duration_s;
    }
    const int finished = ++done_;
    if (o_.progress) {
      std::lock_guard lock(progress_mutex_);
      o_.progress(finished);
    }
  }

  // One session: simulated, written, replayed through the station, its estimate scored against
  // the truth. A step that fails leaves its error in `out`.
  void RunOne(int run, PipelineRun* out) {
    out->seed = o_.seed * 1000003 + static_cast<std::uint64_t>(run);
    sim::SimCapture capture;
    if (!sim::BuildSimCapture(SimulationFor(out->seed), &capture, &out->error)) return;
    // The capture and the state directory are removed whichever way the run ends.
    const RemovedOnExit path((dir_ / fmt::format("run-{}.tcap", run)).string());
    const RemovedOnExit state_dir((dir_ / fmt::format("state-{}", run)).string());
    if (!sim::WriteSimCapture(capture, path.path, &out->error)) return;
    const double offset_s = static_cast<double>(capture.offset_ns) * 1e-9;
    daemon::ReplayOnceOutcome replay;
    if (!Replay(path.path, state_dir.path, offset_s, &replay, out)) return;
    const std::string& device = capture.header.devices.at(0).name;
    nlohmann::json m;
    if (!JudgedEstimate(&replay.result, state_dir.path, device, &m, &out->error)) return;
    Eigen::VectorXd truth;
    if (!Truth(capture, m, offset_s, &truth, &out->error)) return;
    if (chamber_) {
      if (!ScoreInChamber(capture, m, truth, out)) return;
    } else {
      Score(m, truth, out);
    }
    if (!o_.keep_dir.empty() &&
        (!(out->z.cwiseAbs().maxCoeff() <= 4.0) || out->p_value < o_.keep_p_below))
      KeepCapture(path.path, *out);
    out->session_s = capture.session.duration_s;
    const int finished = ++done_;
    if (o_.progress) {
      std::lock_guard lock(progress_mutex_);
      o_.progress(finished);
    }
  }

  // The session a run simulates: the plan (shuffled per run for "shuffled"), the class's noise
  // with the drift the options add, the table.
  sim::SimCaptureOptions SimulationFor(std::uint64_t seed) const {
    sim::SimCaptureOptions o;
    o.protocol = *protocol_;
    (accel_ ? o.accel_model : gyro_ ? o.gyro_model : o.mag_model) = o_.model;
    o.poses = plan_;
    if (o_.plan == "shuffled") {
      std::mt19937_64 rng(seed ^ 0x5eed);
      std::shuffle(o.poses.begin(), o.poses.end(), rng);
    }
    SessionSimOptions& session = o.session;
    session.sensor = sensor_;
    session.sensor.acc_bias_instability *= o_.drift_scale;
    session.sensor.mag_bias_instability *= o_.drift_scale;
    session.sensor.gyr_bias_instability *= o_.drift_scale;
    session.gyr_random_walk = o_.random_walk * sensor_.gyr_bias_instability / 10.0;
    session.dwell_s = o_.dwell_s;
    session.table = table_;
    session.seed = seed;
    session.acc_warmup = o_.warmup * sensor_.acc_bias_instability;
    session.mag_warmup = o_.warmup * sensor_.mag_bias_instability;
    session.gyr_warmup = o_.warmup * sensor_.gyr_bias_instability;
    session.warmup_tau_s = o_.warmup_tau_s;
    if (o_.lever_arm_m.size() == 3) {
      session.lever_arm_q_m =
          Eigen::Vector3d(o_.lever_arm_m[0], o_.lever_arm_m[1], o_.lever_arm_m[2]);
    }
    session.acc_random_walk = o_.random_walk * sensor_.acc_bias_instability / 10.0;
    session.mag_random_walk = o_.random_walk * sensor_.mag_bias_instability / 10.0;
    if (chamber_) {
      session.chamber = chamber_;
      session.repeat_poses_through_chamber = true;
    }
    if (o_.rate_hz > 0) session.rate_hz = o_.rate_hz;
    session.mag_rate_hz = o_.mag_rate_hz;
    return o;
  }

  // The station `turncald --replay --once` runs, with only the model under test.
  daemon::StationOptions StationFor(const std::string& state_dir) const {
    daemon::StationOptions station;
    station.models = {station_model_};
    if (chamber_) {
      station.thermal.fit.t0_c = chamber_->middle_c();
      if (o_.thermal_orders == "truth") station.thermal.fit.orders = truth_basis_.orders;
    }
    station.rate_accuracy = kSimulatedRateAccuracy;
    // The moves between static poses count for "moves" and "all" only (a rate segment between
    // two static poses drops the move anyway).
    station.sequencer.moves.enabled =
        gyro_ && (o_.gyro_sources == "moves" || o_.gyro_sources == "all");
    station.sensor_class = o_.sensor_class;
    station.warmup_in_instabilities = o_.station_warmup;
    station.warmup_tau_s = o_.warmup_tau_s;
    station.drift_model = !o_.independent;
    station.identify_drift = o_.identify_drift;
    if (o_.gate_min_dof >= 0) {
      GateDefaultsForClass(o_.sensor_class, &station.gate);
      station.gate.min_dof = o_.gate_min_dof;
      station.gate_tolerances_set = true;
    }
    if (o_.at == "first-gate") station.state_dir = state_dir;
    for (int u = 0; o_.units > 1 && u < o_.units; ++u) {
      station.per_device[fmt::format("imu{}", u + 1)].mount = mounts_[static_cast<std::size_t>(u)];
    }
    return station;
  }

  // The capture through the station, noting the first activation (poses and session seconds to
  // a passing gate) and the sequencer's rejections.
  // A fixture's (`units`: one run per device, imu1, imu2, ...): each unit's first activation in
  // its own run.
  bool Replay(const std::string& path, const std::string& state_dir, double offset_s,
              daemon::ReplayOnceOutcome* replay, PipelineRun* out,
              std::vector<PipelineRun>* units = nullptr) const {
    const auto on_event = [&](const nlohmann::json& j) {
      PipelineRun* unit = out;
      if (units) {
        const std::string device = j.value("device", "");
        const int k = device.rfind("imu", 0) == 0 ? std::atoi(device.c_str() + 3) - 1 : -1;
        if (k >= 0 && k < static_cast<int>(units->size())) unit = &(*units)[k];
      }
      if (unit->gate_poses < 0 && j.value("class", "") == "CALIBRATION_ACTIVE") {
        unit->gate_poses = j.value("poses", -1);
        unit->gate_s = j.value("t", NAN) - offset_s;
      }
      if (j.value("class", "") == "POSE_REJECTED") out->rejected.push_back(j.value("reason", ""));
    };
    return daemon::ReplayOnce(path, StationFor(state_dir), "", on_event, replay, &out->error);
  }

  // The estimate judged: the result's at the end, or the calibration the gate first activated
  // (version 1: in history/ when later versions replaced it, daemon/state/persistence.h, else
  // the active calibration).
  bool JudgedEstimate(nlohmann::json* result, const std::string& state_dir,
                      const std::string& device, nlohmann::json* m, std::string* error) const {
    if (o_.at == "first-gate") {
      std::ifstream history(
          fmt::format("{}/history/{}.{}.v1.json", state_dir, device, station_model_));
      if (history) {
        *m = nlohmann::json::parse(history, nullptr, false);
      } else {
        daemon::ReadActiveCalibration(state_dir, device, station_model_, m);
      }
      if (!m->is_object() || m->value("version", 0) != 1) {
        *error = "the gate never passed";
        return false;
      }
      (*m)["ok"] = true;
    } else {
      *m = (*result)["devices"][device]["models"][station_model_];
    }
    if (!m->value("ok", false)) {
      *error = "no estimate";
      return false;
    }
    return true;
  }

  // The truth of every parameter: the turn-on bias plus the drift averaged over the
  // calibration's own bias window (the sequencer's window at the latest pose; host time =
  // capture time).
  bool Truth(const sim::SimCapture& capture, const nlohmann::json& m, double offset_s,
             Eigen::VectorXd* truth, std::string* error) const {
    const SimulatedSession& session = capture.session;
    *truth = accel_ ? session.accel_truth : gyro_ ? session.gyro_truth : session.mag_truth;
    TimeWindow window;
    if (protocol::ParseTimeWindow(m["bias_window"], &window)) {
      const double t0 = window.t0_s - offset_s, t1 = window.t1_s - offset_s;
      truth->segment<3>(bias_) += accel_  ? session.AccDriftMean(t0, t1)
                                  : gyro_ ? session.GyrDriftMean(t0, t1)
                                          : session.MagDriftMean(t0, t1);
    } else if (o_.independent && !gyro_) {
      // The model before issue 19 has no bias window: its bias is, near enough, the drift's
      // mean over the dwells.
      truth->segment<3>(bias_) +=
          accel_ ? session.EffectiveAccBiasOffset() : session.EffectiveMagBiasOffset();
    } else {
      *error = "the result has no bias window";
      return false;
    }
    return true;
  }

  // z per parameter, the fit check's p-value, the gate and the poses of the estimate `m`.
  void Score(const nlohmann::json& m, const Eigen::VectorXd& truth, PipelineRun* out) const {
    const int n = model_->num_parameters();
    out->z.resize(n);
    for (int i = 0; i < n; ++i) {
      const auto& p = m["params"][model_->parameters()[static_cast<std::size_t>(i)].name];
      const double sigma = p["sigma"].is_number() ? p["sigma"].get<double>() : NAN;
      out->z[i] = (p["value"].get<double>() - truth[i]) / sigma;
    }
    out->ok = out->z.allFinite();
    out->p_value = m.value("p_value", 1.0);
    out->gate_pass = m["gate"].value("pass", false);
    if (m["gate"].contains("reasons")) out->gate_reasons = m["gate"]["reasons"];
    // A calibration document counts its poses in its estimate; the result in the model.
    out->poses = m.value("poses", o_.at == "first-gate" ? out->gate_poses : 0);
  }

  // In a chamber: z per scored name (ThermalScoredNames), against the session's truth over
  // temperature with the biases' wander over the calibration's bias window (`truth`'s biases
  // minus the turn-on ones).
  bool ScoreInChamber(const sim::SimCapture& capture, const nlohmann::json& m,
                      const Eigen::VectorXd& truth, PipelineRun* out) const {
    const SimulatedSession& session = capture.session;
    const std::optional<ThermalTruth>& thermal = accel_  ? session.accel_thermal
                                                 : gyro_ ? session.gyro_thermal
                                                         : session.mag_thermal;
    const Eigen::VectorXd& turn_on = accel_  ? session.accel_truth
                                     : gyro_ ? session.gyro_truth
                                             : session.mag_truth;
    if (!thermal) {
      out->error = "the session has no truth over temperature";
      return false;
    }
    const Eigen::Vector3d wander = truth.segment<3>(bias_) - turn_on.segment<3>(bias_);
    if (!ScoreThermalRun(*model_, m, *thermal, wander, o_.thermal_orders == "truth", held_out_c_,
                         &out->z, &out->error)) {
      return false;
    }
    out->ok = out->z.allFinite();
    out->p_value = m.contains("temperature") ? m["temperature"].value("p_value", 1.0) : 1.0;
    out->gate_pass = m["gate"].value("pass", false);
    if (m["gate"].contains("reasons")) out->gate_reasons = m["gate"]["reasons"];
    out->poses = m.value("poses", 0);
    return true;
  }

  // A run with a parameter beyond 4 sigma (or a chi^2 p-value below keep_p_below) keeps its
  // capture, for turncald --replay.
  void KeepCapture(const std::string& path, const PipelineRun& run) const {
    std::error_code ec;
    std::filesystem::create_directories(o_.keep_dir, ec);
    std::filesystem::copy_file(path, fmt::format("{}/run-{}.tcap", o_.keep_dir, run.seed),
                               std::filesystem::copy_options::overwrite_existing, ec);
  }

  // The z-scores, p-values, gate and session figures over the runs with an estimate.
  void Summarise(PipelineMonteCarloSummary* s) const {
    s->z = ZScoreSummary(static_cast<int>(s->parameters.size()));
    double poses = 0, session_s = 0, gate_poses = 0, gate_s = 0;
    const std::vector<double> p_values = AddSolvedRuns(s, [&](const PipelineRun& r) {
      s->gate_pass += r.gate_pass;
      if (r.gate_poses > 0) {
        ++s->activated;
        gate_poses += r.gate_poses;
        s->poses_to_gate_max = std::max(s->poses_to_gate_max, r.gate_poses);
        gate_s += r.gate_s;
      }
      poses += r.poses;
      session_s += r.session_s;
    });
    for (int u = 0; o_.units > 1 && u < o_.units; ++u) {
      s->unit_z.emplace_back(static_cast<int>(s->parameters.size()));
      s->unit_mounts.push_back(sim::kFixtureMounts[u % 4]);
      for (const auto& r : s->runs) {
        if (r.ok && r.unit == u) s->unit_z.back().Add(r.z);
      }
    }
    if (s->solved < 2) return;
    s->ks = KsUniform(p_values);
    s->poses_mean = poses / s->solved;
    s->session_s_mean = session_s / s->solved;
    if (s->activated > 0) {
      s->poses_to_gate = gate_poses / s->activated;
      s->seconds_to_gate = gate_s / s->activated;
    }
  }

  const PipelineMonteCarloOptions& o_;
  std::optional<drivers::Protocol> protocol_;
  std::unique_ptr<MeasurementModel> model_;
  SensorClass sensor_;
  bool accel_ = false, gyro_ = false;
  int bias_ = -1;  // where the triad's bias starts in the model's parameters
  std::optional<TableMotion> table_;
  std::vector<TablePose> plan_;
  std::string station_model_;  // o_.model, or MODEL@T in a chamber
  std::optional<ChamberProfile> chamber_;
  ThermalBasis truth_basis_;
  std::vector<double> held_out_c_;
  std::vector<Mat3<double>> mounts_;  // each unit's of a fixture (sim::kFixtureMounts)
  std::filesystem::path dir_;
  std::atomic<int> done_{0};
  std::mutex progress_mutex_;
};

}  // namespace

bool PipelineMonteCarloSummary::Passed() const {
  int honest = 0;
  for (int i = 0; i < z.parameters(); ++i) honest += z.Honest(i);
  for (const auto& u : unit_z) {
    for (int i = 0; i < u.parameters(); ++i) honest -= !UnitHonest(u, i);
  }
  return honest == z.parameters() && ks.p > 0.01 && solved == static_cast<int>(runs.size());
}

bool PipelineMonteCarloSummary::UnitHonest(const ZScoreSummary& u, int parameter) {
  const double n = u.runs();
  if (n < 2) return false;
  const double std_z = u.Std()[parameter], mean_z = u.Mean()[parameter];
  return std::abs(std_z - 1.0) <= kUnitHonestZ / std::sqrt(2.0 * n) &&
         std::abs(mean_z) <= kUnitHonestZ / std::sqrt(n);
}

PipelineMonteCarloSummary RunPipelineMonteCarlo(const PipelineMonteCarloOptions& options) {
  return PipelineMonteCarlo(options).Run();
}

}  // namespace turncal::montecarlo
