#include "tools/pipeline_montecarlo.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <random>
#include <thread>

#include "core/planning/pose_planner.h"
#include "core/sequencing/sequencer.h"
#include "daemon/persistence.h"
#include "daemon/replay_once.h"
#include "protocol/calibration_json.h"
#include "sim/capture.h"
#include "sim/session_sim.h"
#include "sim/synthetic.h"
#include "tools/ks_uniform.h"

namespace turncal::tools {

namespace {

// The rates the planner may give a gyroscope's rate segments: sim/session_sim.h's defaults.
const std::vector<double> kPlannedRatesDps = {100.0, -100.0, 100.0 / 3, -100.0 / 3};

// The D-optimal planner's plan to the gate from nominal values, for the accelerometer and
// magnetometer models a station calibrates together (what `turncal plan --model accel13 --model
// mag13` prints), or for a gyroscope model alone with the rate segments and moves its sources
// allow (`turncal plan --model gyro12 [--rates ...] [--no-moves]`): the recommended pose and its
// continuation, for the simulated table.
std::vector<TablePose> PlannerSequence(const SensorClass& sensor,
                                       const PipelineMonteCarloArgs& args,
                                       const std::optional<TableMotion>& table, double rate_hz,
                                       bool gyro, int* predicted_poses, std::string* error) {
  std::vector<std::unique_ptr<MeasurementModel>> models;
  std::vector<PlanningTarget> targets;
  // A gyroscope's records are what the station captures: its sequencer's dwell (whole
  // revolutions of at least it for a rate segment) of the simulator's longer rest, the rest of
  // which lengthens each move (the station measures the same on the moves it captures).
  const double station_dwell_s = SequencerOptions{}.dwell_s;
  const double dwell_s = gyro ? std::min(args.dwell_s, station_dwell_s) : args.dwell_s;
  const std::vector<std::string> names =
      gyro ? std::vector<std::string>{args.model} : std::vector<std::string>{"accel13", "mag13"};
  for (const std::string& name : names) {
    auto model = MakeModel(name, ModelContext{}, error);
    if (!model) return {};
    PlanningTarget t;
    t.model = model.get();
    t.theta = model->nominal();
    CalibratorOptions o = args.planner_drift == "independent"
                              ? OptionsForClass(*model, sensor)
                              : DriftOptionsForClass(*model, sensor);
    t.sqrt_information = ExpectedPoseSqrtInformation(*model, sensor, o, dwell_s, rate_hz);
    t.drift = o.drift;
    t.pose_offset_sigma = o.pose_offset_sigma;
    if (gyro) {
      t.noise_density = o.noise_density;
      t.rate_accuracy = 2e-6;  // the station's in these runs (below)
    }
    GateDefaultsForClass(args.sensor_class, &t.gate);
    targets.push_back(t);
    models.push_back(std::move(model));
  }
  PlannerOptions options;
  if (gyro) {
    if (args.gyro_sources != "moves") options.rates.rates_dps = kPlannedRatesDps;
    options.moves = args.gyro_sources == "moves" || args.gyro_sources == "all";
    options.move_rest_s = std::max(0.0, args.dwell_s - station_dwell_s);
  }
  options.dwell_s = dwell_s;
  options.objective =
      args.planner_objective == "poses" ? PlanObjective::kPoses : PlanObjective::kTime;
  if (table) {
    options.motion = *table;
  } else {
    // The simulator's fixed moves: every pose costs the same time, only the drift's timing counts.
    options.motion.rate_dps.setConstant(1e6);
    options.motion.accel_dps2.setConstant(1e12);
    options.motion.settle_s = SessionSimOptions{}.move_s + SessionSimOptions{}.settle_s;
  }
  // A whole session's plan, as long as the default one, so that the gate's first pass is the
  // station's and the estimate at the end is judged after as many poses as the other plans.
  options.min_continuation = static_cast<int>(DefaultSessionPoses().size());
  const NextPoseAdvice a = PlanNextPose(targets, options);
  if (!a.ok) {
    *error = "the planner: " + a.error;
    return {};
  }
  *predicted_poses = a.poses_to_gate;
  return a.continuation;
}

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

struct RunOutcome {
  bool ok = false;
  std::string error;
  Eigen::VectorXd z;
  double p_value = 1.0;
  bool gate_pass = false;
  nlohmann::json gate_reasons = nlohmann::json::array();  // the gate's reasons at the end
  nlohmann::json rejected = nlohmann::json::array();      // the sequencer's rejection reasons
  int poses = 0;
  double session_s = 0.0;
  std::uint64_t seed = 0;
  int gate_poses = -1;  // poses at the first activation (-1: never)
  double gate_s = NAN;  // session seconds at the first activation
};

}  // namespace

int RunPipelineMonteCarlo(const PipelineMonteCarloArgs& args) {
  const auto protocol = drivers::ParseProtocol(args.protocol);
  std::string error;
  auto model = MakeModel(args.model, ModelContext{}, &error);
  SensorClass sensor;
  if (!protocol || !model || !SensorClassByName(args.sensor_class, &sensor)) {
    fmt::print(stderr, "turncal montecarlo: {}\n",
               !protocol ? "unknown protocol '" + args.protocol + "'"
               : !model  ? error
                         : "unknown class '" + args.sensor_class + "'");
    return 2;
  }
  const SensorKind kind = model->sensor();
  const bool accel = kind == SensorKind::kAccelerometer;
  const bool gyro = kind == SensorKind::kGyroscope;
  const int bias = model->index_of("bx");
  std::optional<TableMotion> table;
  if (args.table_rate_dps > 0) {
    table.emplace();
    table->rate_dps.setConstant(args.table_rate_dps);
    table->accel_dps2.setConstant(args.table_accel_dps2);
    table->settle_s = SessionSimOptions{}.settle_s;
  }
  std::vector<TablePose> plan = DefaultSessionPoses();
  int predicted_poses = -1;  // the planner's prediction of the gate
  if (args.plan == "planner") {
    plan = PlannerSequence(sensor, args, table, sim::SimDefaultRateHz(*protocol), gyro,
                           &predicted_poses, &error);
    if (plan.empty()) {
      fmt::print(stderr, "turncal montecarlo: {}\n", error);
      return 1;
    }
  }
  if (gyro && args.plan == "planner") {
    // The planner placed the rate segments its sources allow.
  } else if (gyro && args.gyro_sources == "all") {
    // The static poses (and the moves between them), then the rate segments.
    for (const TablePose& r : DefaultRateSegments()) plan.push_back(r);
  } else if (gyro && args.gyro_sources != "moves") {
    // Rate segments after the first static poses, or alone.
    const std::vector<TablePose> rates = DefaultRateSegments();
    std::vector<TablePose> mixed;
    const std::vector<TablePose> statics =
        args.gyro_sources == "rates" ? std::vector<TablePose>{} : plan;
    for (std::size_t i = 0; i < std::max(statics.size(), rates.size()); ++i) {
      if (i < statics.size()) mixed.push_back(statics[i]);
      if (i < rates.size()) mixed.push_back(rates[i]);
    }
    plan = mixed;
  }
  const int N = model->num_parameters();
  const auto dir = std::filesystem::temp_directory_path() /
                   fmt::format("turncal-montecarlo-{}", static_cast<long>(::getpid()));
  std::filesystem::create_directories(dir);

  std::vector<RunOutcome> outcomes(static_cast<std::size_t>(args.runs));
  std::atomic<int> next{0}, done{0};
  std::mutex print_mutex;
  const auto start = std::chrono::steady_clock::now();
  auto worker = [&] {
    for (int run = next++; run < args.runs; run = next++) {
      RunOutcome& out = outcomes[static_cast<std::size_t>(run)];
      const std::uint64_t seed = args.seed * 1000003 + static_cast<std::uint64_t>(run);
      out.seed = seed;
      sim::SimCaptureOptions o;
      o.protocol = *protocol;
      (accel ? o.accel_model : gyro ? o.gyro_model : o.mag_model) = args.model;
      o.poses = plan;
      if (args.plan == "shuffled") {
        std::mt19937_64 rng(seed ^ 0x5eed);
        std::shuffle(o.poses.begin(), o.poses.end(), rng);
      }
      o.session.sensor = sensor;
      o.session.sensor.acc_bias_instability *= args.drift_scale;
      o.session.sensor.mag_bias_instability *= args.drift_scale;
      o.session.sensor.gyr_bias_instability *= args.drift_scale;
      o.session.gyr_random_walk = args.random_walk * sensor.gyr_bias_instability / 10.0;
      o.session.dwell_s = args.dwell_s;
      o.session.table = table;
      o.session.seed = seed;
      o.session.acc_warmup = args.warmup * sensor.acc_bias_instability;
      o.session.mag_warmup = args.warmup * sensor.mag_bias_instability;
      o.session.gyr_warmup = args.warmup * sensor.gyr_bias_instability;
      o.session.warmup_tau_s = args.warmup_tau_s;
      if (args.lever_arm_m.size() == 3) {
        o.session.lever_arm_q_m =
            Eigen::Vector3d(args.lever_arm_m[0], args.lever_arm_m[1], args.lever_arm_m[2]);
      }
      o.session.acc_random_walk = args.random_walk * sensor.acc_bias_instability / 10.0;
      o.session.mag_random_walk = args.random_walk * sensor.mag_bias_instability / 10.0;
      sim::SimCapture capture;
      std::string e;
      if (!sim::BuildSimCapture(o, &capture, &e)) {
        out.error = e;
        continue;
      }
      // The capture and the state directory are removed whichever way the run ends.
      const RemovedOnExit path((dir / fmt::format("run-{}.tcap", run)).string());
      const RemovedOnExit state_dir((dir / fmt::format("state-{}", run)).string());
      if (!sim::WriteSimCapture(capture, path.path, &e)) {
        out.error = e;
        continue;
      }
      daemon::StationOptions station;
      station.models = {args.model};
      // The simulated table's rate accuracy: its ripple (1e-4 at 2 Hz, phase drawn per segment)
      // averages to ~2e-6 of the rate over a revolution at 100 deg/s (1e-4 / (2 pi 2 Hz 3.6 s)).
      station.rate_accuracy = 2e-6;
      // The moves between static poses count for "moves" and "all" only (a rate segment between
      // two static poses drops the move anyway).
      station.sequencer.moves.enabled =
          gyro && (args.gyro_sources == "moves" || args.gyro_sources == "all");
      station.sensor_class = args.sensor_class;
      station.warmup_in_instabilities = args.station_warmup;
      station.warmup_tau_s = args.warmup_tau_s;
      station.drift_model = !args.independent;
      station.identify_drift = args.identify_drift;
      if (args.gate_min_dof >= 0) {
        GateDefaultsForClass(args.sensor_class, &station.gate);
        station.gate.min_dof = args.gate_min_dof;
        station.gate_tolerances_set = true;
      }
      if (args.at == "first-gate") station.state_dir = state_dir.path;
      daemon::ReplayOnceOutcome replay;
      const double offset_s = static_cast<double>(capture.offset_ns) * 1e-9;
      // The first activation: poses and session seconds to a passing gate.
      const auto on_event = [&](const nlohmann::json& j) {
        if (out.gate_poses < 0 && j.value("class", "") == "CALIBRATION_ACTIVE") {
          out.gate_poses = j.value("poses", -1);
          out.gate_s = j.value("t", NAN) - offset_s;
        }
        if (j.value("class", "") == "POSE_REJECTED") out.rejected.push_back(j.value("reason", ""));
      };
      if (!daemon::ReplayOnce(path.path, station, "", on_event, &replay, &e)) {
        out.error = e;
        continue;
      }
      const std::string& device = capture.header.devices.at(0).name;
      nlohmann::json first;
      if (args.at == "first-gate") {
        // Version 1: in history/ when later versions replaced it (daemon/persistence.h), else the
        // active calibration.
        std::ifstream history(
            fmt::format("{}/history/{}.{}.v1.json", state_dir.path, device, args.model));
        if (history) {
          first = nlohmann::json::parse(history, nullptr, false);
        } else {
          daemon::ReadActiveCalibration(state_dir.path, device, args.model, &first);
        }
        if (!first.is_object() || first.value("version", 0) != 1) {
          out.error = "the gate never passed";
          continue;
        }
        first["ok"] = true;
      }
      const nlohmann::json& m =
          args.at == "first-gate" ? first : replay.result["devices"][device]["models"][args.model];
      if (!m.value("ok", false)) {
        out.error = "no estimate";
        continue;
      }
      // The bias truth: the turn-on bias plus the drift averaged over the calibration's own bias
      // window (the sequencer's window at the latest pose; host time = capture time).
      Eigen::VectorXd truth = accel  ? capture.session.accel_truth
                              : gyro ? capture.session.gyro_truth
                                     : capture.session.mag_truth;
      TimeWindow window;
      if (protocol::ParseTimeWindow(m["bias_window"], &window)) {
        const double t0 = window.t0_s - offset_s, t1 = window.t1_s - offset_s;
        truth.segment<3>(bias) += accel  ? capture.session.AccDriftMean(t0, t1)
                                  : gyro ? capture.session.GyrDriftMean(t0, t1)
                                         : capture.session.MagDriftMean(t0, t1);
      } else if (args.independent && !gyro) {
        // The model before issue 19 has no bias window: its bias is, near enough, the drift's
        // mean over the dwells.
        truth.segment<3>(bias) += accel ? capture.session.EffectiveAccBiasOffset()
                                        : capture.session.EffectiveMagBiasOffset();
      } else {
        out.error = "the result has no bias window";
        continue;
      }
      out.z.resize(N);
      for (int i = 0; i < N; ++i) {
        const auto& p = m["params"][model->parameters()[static_cast<std::size_t>(i)].name];
        const double sigma = p["sigma"].is_number() ? p["sigma"].get<double>() : NAN;
        out.z[i] = (p["value"].get<double>() - truth[i]) / sigma;
      }
      out.ok = out.z.allFinite();
      if (!args.keep_dir.empty() && !(out.z.cwiseAbs().maxCoeff() <= 4.0)) {
        std::error_code ec;
        std::filesystem::create_directories(args.keep_dir, ec);
        std::filesystem::copy_file(path.path, fmt::format("{}/run-{}.tcap", args.keep_dir, seed),
                                   std::filesystem::copy_options::overwrite_existing, ec);
      }
      out.p_value = m.value("p_value", 1.0);
      out.gate_pass = m["gate"].value("pass", false);
      if (m["gate"].contains("reasons")) out.gate_reasons = m["gate"]["reasons"];
      // A calibration document counts its poses in its estimate; the result in the model.
      out.poses = m.value("poses", args.at == "first-gate" ? out.gate_poses : 0);
      out.session_s = capture.session.duration_s;
      if (const int finished = ++done; !args.json && finished % 20 == 0) {
        std::lock_guard lock(print_mutex);
        fmt::print(stderr, "turncal montecarlo: {} of {} runs\n", finished, args.runs);
      }
    }
  };
  std::vector<std::thread> threads;
  for (int j = 0; j < std::max(1, args.jobs); ++j) threads.emplace_back(worker);
  for (auto& t : threads) t.join();
  std::filesystem::remove_all(dir);
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  if (!args.runs_out.empty()) {
    std::FILE* f = std::fopen(args.runs_out.c_str(), "w");
    if (f == nullptr) {
      fmt::print(stderr, "turncal montecarlo: cannot write '{}'\n", args.runs_out);
      return 2;
    }
    for (const auto& r : outcomes) {
      nlohmann::json z = nlohmann::json::object();
      for (int i = 0; r.ok && i < N; ++i) {
        z[model->parameters()[static_cast<std::size_t>(i)].name] = r.z[i];
      }
      fmt::print(f, "{}\n",
                 nlohmann::json{{"seed", r.seed},
                                {"ok", r.ok},
                                {"gate_poses", r.gate_poses},
                                {"gate_s", r.gate_s},
                                {"error", r.error},
                                {"z", z},
                                {"p_value", r.p_value},
                                {"gate_pass", r.gate_pass},
                                {"gate_reasons", r.gate_reasons},
                                {"rejected", r.rejected},
                                {"poses", r.poses}}
                     .dump());
    }
    std::fclose(f);
  }
  Eigen::VectorXd s1 = Eigen::VectorXd::Zero(N), s2 = Eigen::VectorXd::Zero(N);
  std::vector<double> p_values;
  int ok = 0, gate_pass = 0, activated = 0;
  double poses = 0, session_s = 0, gate_poses = 0, gate_s = 0;
  int gate_poses_max = 0;
  std::string first_error;
  for (const auto& r : outcomes) {
    if (!r.ok) {
      if (first_error.empty()) first_error = r.error;
      continue;
    }
    ++ok;
    s1 += r.z;
    s2 += r.z.cwiseAbs2();
    p_values.push_back(r.p_value);
    gate_pass += r.gate_pass;
    if (r.gate_poses > 0) {
      ++activated;
      gate_poses += r.gate_poses;
      gate_poses_max = std::max(gate_poses_max, r.gate_poses);
      gate_s += r.gate_s;
    }
    poses += r.poses;
    session_s += r.session_s;
  }
  if (ok < 2) {
    fmt::print(stderr, "turncal montecarlo: {} of {} runs gave an estimate ({})\n", ok, args.runs,
               first_error);
    return 1;
  }
  const Eigen::VectorXd mean = s1 / ok;
  const Eigen::VectorXd std_z = (s2 / ok - mean.cwiseAbs2()).cwiseMax(0.0).cwiseSqrt();
  const auto [ks_d, ks_p] = KsUniform(p_values);
  int bad = 0;
  nlohmann::json rows = nlohmann::json::array();
  std::string z_table = "| param | mean z | std z | verdict |\n|---|---|---|---|\n";
  for (int i = 0; i < N; ++i) {
    const bool honest = std_z[i] >= 0.9 && std_z[i] <= 1.1 && std::abs(mean[i]) <= 0.15;
    bad += !honest;
    const std::string& name = model->parameters()[static_cast<std::size_t>(i)].name;
    rows.push_back({{"name", name}, {"mean_z", mean[i]}, {"std_z", std_z[i]}, {"honest", honest}});
    z_table += fmt::format("| {} | {:+.3f} | {:.3f} | {} |\n", name, mean[i], std_z[i],
                           honest ? "ok" : "NOT HONEST");
  }
  const bool ks_ok = ks_p > 0.01;
  if (args.json) {
    fmt::print("{}\n", nlohmann::json{{"model", args.model},
                                      {"class", args.sensor_class},
                                      {"protocol", args.protocol},
                                      {"plan", args.plan},
                                      {"planner_predicted_poses", predicted_poses},
                                      {"gyro_sources", gyro ? args.gyro_sources : ""},
                                      {"planner_objective", args.planner_objective},
                                      {"planner_drift", args.planner_drift},
                                      {"table_rate_dps", args.table_rate_dps},
                                      {"warmup", args.warmup},
                                      {"random_walk", args.random_walk},
                                      {"lever_arm_m", args.lever_arm_m},
                                      {"drift_scale", args.drift_scale},
                                      {"identify_drift", args.identify_drift},
                                      {"station_warmup", args.station_warmup},
                                      {"runs", args.runs},
                                      {"solved", ok},
                                      {"poses_mean", poses / ok},
                                      {"gate_pass", gate_pass},
                                      {"independent", args.independent},
                                      {"activated", activated},
                                      {"poses_to_gate", activated ? gate_poses / activated : NAN},
                                      {"poses_to_gate_max", gate_poses_max},
                                      {"seconds_to_gate", activated ? gate_s / activated : NAN},
                                      {"chi2_ks_d", ks_d},
                                      {"chi2_ks_p", ks_p},
                                      {"params", rows}}
                           .dump());
  } else {
    fmt::print(
        "Monte Carlo through the pipeline: {} runs of {} ({} class, {}, plan {}{}{}; {:.0f} "
        "poses and {:.0f} s of session on average), seed {}; {} solved; {:.1f} s wall, {} "
        "jobs\n\n{}",
        args.runs, args.model, args.sensor_class, args.protocol,
        args.plan +
            (args.plan == "planner"
                 ? fmt::format(" for {}, {} drift", args.planner_objective, args.planner_drift)
                 : std::string()) +
            (args.table_rate_dps > 0 ? fmt::format(", table {:g} deg/s", args.table_rate_dps)
                                     : std::string()),
        args.warmup > 0 ? fmt::format(", warm-up {} x bias instability", args.warmup) : "",
        (args.random_walk > 0 ? fmt::format(", random walk {}", args.random_walk) : "") +
            (args.lever_arm_m.size() == 3
                 ? fmt::format(", lever arm [{:g}, {:g}, {:g}] m", args.lever_arm_m[0],
                               args.lever_arm_m[1], args.lever_arm_m[2])
                 : std::string()) +
            (args.station_warmup >= 0
                 ? fmt::format(", station warm-up allowance {}", args.station_warmup)
                 : std::string()),
        poses / ok, session_s / ok, args.seed, ok, wall_s, args.jobs, z_table);
    fmt::print(
        "\nchi^2 p-values against uniform: Kolmogorov-Smirnov D = {:.3f}, p = {:.3g} ({})\n"
        "gate passed in {} of {} runs; first passed after {:.2f} poses (at most {}) and {:.1f} s "
        "of session on average ({} runs){}\n"
        "Criteria: std z in [0.9, 1.1] and |mean z| <= 0.15 for every parameter, KS p > 0.01; "
        "{} of {} parameters fail{}.\n",
        ks_d, ks_p, ks_ok ? "ok" : "NOT UNIFORM", gate_pass, ok,
        activated ? gate_poses / activated : NAN, gate_poses_max,
        activated ? gate_s / activated : NAN, activated,
        predicted_poses > 0
            ? fmt::format("; the planner predicted it after {} poses", predicted_poses)
            : "",
        bad, N,
        ok < args.runs
            ? fmt::format("; {} runs without an estimate (first: {})", args.runs - ok, first_error)
            : "");
  }
  return bad == 0 && ks_ok && ok == args.runs ? 0 : 1;
}

}  // namespace turncal::tools
