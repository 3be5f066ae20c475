#include "tools/sim_fit_command.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/analysis/publish_gate.h"
#include "core/estimation/calibrator.h"
#include "core/modeling/accel_physical.h"
#include "protocol/observability_json.h"
#include "sim/session_sim.h"
#include "sim/synthetic.h"
#include "tools/pipeline_montecarlo.h"

namespace turncal::tools {

namespace {

struct SimArgs {
  std::string model = "accel13";
  std::string sensor_class = "industrial";
  int poses = 26;
  std::string design = "cube";
  double dwell_s = 5.0;
  std::uint64_t seed = 1;
  int runs = 200;
  bool json = false;
  std::string noise = "white";               // montecarlo: white | session
  std::string drift_model = "gauss-markov";  // montecarlo --noise session: | independent
  bool shuffle = false;                      // montecarlo: the design's poses in random order
};

void AddSimOptions(CLI::App* cmd, SimArgs* args) {
  cmd->add_option("--model", args->model, "accel12|accel13|mag13|mag22|mag-physical")
      ->capture_default_str();
  cmd->add_option("--class", args->sensor_class, "sensor class: industrial|consumer (SENSORS.md)")
      ->check(CLI::IsMember({"industrial", "consumer"}))
      ->capture_default_str();
  cmd->add_option("--poses", args->poses, "number of poses")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  cmd->add_option("--design", args->design,
                  "pose design: cube (26 cube directions, repeated) | random | about-z")
      ->check(CLI::IsMember({"cube", "random", "about-z"}))
      ->capture_default_str();
  cmd->add_option("--dwell", args->dwell_s, "seconds averaged per pose")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--seed", args->seed, "random seed")->capture_default_str();
  cmd->add_flag("--json", args->json, "JSON output");
}

std::vector<TablePose> Design(const SimArgs& args, std::mt19937_64* rng) {
  if (args.design == "random") return RandomPoses(args.poses, rng);
  if (args.design == "about-z") return AboutZPoses(args.poses);
  const auto cube = CubePoses26();
  std::vector<TablePose> poses;
  for (int i = 0; i < args.poses; ++i) {
    TablePose p = cube[i % cube.size()];
    const int repeat = i / static_cast<int>(cube.size());
    p.psi_rad += repeat * M_PI / 4;  // repeats turn by 45 deg
    poses.push_back(p);
  }
  return poses;
}

// The model and sensor class the arguments name; nullptr (with the error printed) when unknown.
std::unique_ptr<MeasurementModel> LoadModel(const SimArgs& args, const char* command,
                                            SensorClass* sensor) {
  SensorClassByName(args.sensor_class, sensor);  // CLI11 already restricted the name
  std::string error;
  auto model = MakeModel(args.model, ModelContext{}, &error);
  if (!model) fmt::print(stderr, "turncal {}: {}\n", command, error);
  return model;
}

int RunFit(const SimArgs& args) {
  SensorClass sensor;
  auto model = LoadModel(args, "fit-sim", &sensor);
  if (!model) return 2;
  std::string error;
  std::mt19937_64 rng(args.seed);
  const Eigen::VectorXd truth = DrawTruth(*model, sensor, &rng);
  Calibrator calibrator(OptionsForClass(*model, sensor));
  for (const auto& pose : Design(args, &rng)) {
    if (!calibrator.add_pose(SimulateRecord(*model, truth, pose, sensor, args.dwell_s, &rng),
                             &error)) {
      fmt::print(stderr, "turncal fit-sim: {}\n", error);
      return 2;
    }
  }
  const Estimate e = calibrator.solve();
  // The publish gate with the class's default tolerances (docs/OBSERVABILITY.md).
  GateResult gate;
  if (e.ok) {
    GateOptions gate_options;
    GateDefaultsForClass(sensor.name, &gate_options);
    const DataReport data =
        AnalyzeData(*model, e.theta, calibrator.weighted_poses(), ObservabilityOptions{});
    gate = EvaluateGate(*model, e, data, gate_options);
  } else {
    gate.reasons.push_back("no estimate: " + e.error);
  }
  if (args.json) {
    nlohmann::json params;
    for (std::size_t i = 0; i < e.parameters.size(); ++i) {
      const auto k = static_cast<Eigen::Index>(i);
      params[e.parameters[i].name] = {{"value", e.ok ? e.theta[k] : NAN},
                                      {"sigma", e.ok ? e.sigma[k] : NAN},
                                      {"truth", truth[k]}};
    }
    fmt::print("{}\n", nlohmann::json{{"model", e.model},
                                      {"ok", e.ok},
                                      {"error", e.error},
                                      {"poses", e.poses},
                                      {"rank", e.rank},
                                      {"chi2", e.chi2},
                                      {"dof", e.dof},
                                      {"p_value", e.p_value},
                                      {"gauge", e.gauge},
                                      {"warnings", e.warnings},
                                      {"gate", ToJson(gate)},
                                      {"params", params}}
                           .dump());
    return e.ok ? 0 : 1;
  }
  fmt::print("Simulated {} session: {} class, {} poses ({} design), {:.1f} s dwell, seed {}\n",
             args.model, sensor.name, args.poses, args.design, args.dwell_s, args.seed);
  fmt::print("{}\n", e.BriefReport());
  if (!e.ok) return 1;
  fmt::print("\n  {:<8} {:>14} {:>14} {:>11}  {:<7} {:>7}\n", "param", "truth", "estimate",
             "1 sigma", "unit", "z");
  int beyond = 0;
  for (std::size_t i = 0; i < e.parameters.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    const auto& p = e.parameters[i];
    const auto [t, unit] = ForDisplay(p, truth[k], false);
    const auto [v, unused] = ForDisplay(p, e.theta[k], false);
    const auto [s, unused2] = ForDisplay(p, e.sigma[k], true);
    const double z = (e.theta[k] - truth[k]) / e.sigma[k];
    beyond += std::abs(z) > 3;
    fmt::print("  {:<8} {:>14.6g} {:>14.6g} {:>11.3g}  {:<7} {:>+7.2f}\n", p.name, t, v, s, unit,
               z);
  }
  if (model->sensor() == SensorKind::kAccelerometer) {
    AccelPhysical phys;
    phys.S = e.theta.segment<3>(0);
    phys.alpha = e.theta.segment<3>(3);
    phys.eps = e.theta.segment<3>(6);
    const Mat3<double> G = AccelGFromPhysical(phys, model->context().mounting);
    fmt::print("\n  G = (I+S) T_r^s C_q^r (the linear form's matrix):\n");
    for (int r = 0; r < 3; ++r)
      fmt::print("    [{:+.9f} {:+.9f} {:+.9f}]\n", G(r, 0), G(r, 1), G(r, 2));
  }
  for (const auto& w : e.warnings) fmt::print("  warning: {}\n", w);
  fmt::print("\n  z = (estimate - truth) / sigma; {} of {} parameters beyond 3 sigma.\n", beyond,
             e.parameters.size());
  fmt::print("\n  publish gate ({} tolerances): {}\n", sensor.name, gate.pass ? "PASS" : "FAIL");
  for (const auto& r : gate.reasons) fmt::print("    reason: {}\n", r);
  for (const auto& n : gate.notes) fmt::print("    note: {}\n", n);
  return 0;
}

int RunMonteCarlo(const SimArgs& args) {
  SensorClass sensor;
  auto model = LoadModel(args, "montecarlo", &sensor);
  if (!model) return 2;
  std::string error;
  const int N = model->num_parameters();
  // One pose design for every run (the Cramer-Rao bound depends on it); new truth and noise each
  // run.
  std::mt19937_64 design_rng(args.seed);
  auto poses = Design(args, &design_rng);
  if (args.shuffle) std::shuffle(poses.begin(), poses.end(), design_rng);
  Eigen::VectorXd sum_sq_err = Eigen::VectorXd::Zero(N), sum_var = Eigen::VectorXd::Zero(N),
                  sum_z = Eigen::VectorXd::Zero(N), sum_z2 = Eigen::VectorXd::Zero(N);
  int ok = 0, failed = 0;
  double solve_time = 0;
  // For --noise session the other sensor's model only feeds the simulator.
  const bool accel = model->sensor() == SensorKind::kAccelerometer;
  auto other = MakeModel(accel ? "mag13" : "accel13", ModelContext{}, &error);
  for (int run = 0; run < args.runs; ++run) {
    std::mt19937_64 rng(args.seed * 1000003 + static_cast<std::uint64_t>(run));
    Eigen::VectorXd truth;
    const bool drift = args.noise == "session" && args.drift_model == "gauss-markov";
    Calibrator calibrator(drift ? DriftOptionsForClass(*model, sensor)
                                : OptionsForClass(*model, sensor));
    if (args.noise == "session") {
      // The simulator's full noise model: Gauss-Markov bias wander sampled at the output rate,
      // quantisation, settling; dwell windows cut at the known times.
      SessionSimOptions o;
      o.sensor = sensor;
      o.rate_hz = 100;
      o.dwell_s = args.dwell_s;
      o.seed = args.seed * 1000003 + static_cast<std::uint64_t>(run);
      const SimulatedSession session = accel ? SimulateSession(*model, *other, poses, o)
                                             : SimulateSession(*other, *model, poses, o);
      truth = accel ? session.accel_truth : session.mag_truth;
      // The bias the calibration estimates: over the last pose with the drift model, averaged
      // over the dwells with independent offsets.
      if (drift) {
        truth.tail<3>() +=
            accel ? session.LastPoseAccBiasOffset() : session.LastPoseMagBiasOffset();
      } else {
        truth.tail<3>() +=
            accel ? session.EffectiveAccBiasOffset() : session.EffectiveMagBiasOffset();
      }
      for (const auto& e : session.events) {
        calibrator.add_pose(DwellRecord(session, e, model->sensor()), &error);
      }
    } else {
      truth = DrawTruth(*model, sensor, &rng);
      for (const auto& pose : poses) {
        calibrator.add_pose(SimulateRecord(*model, truth, pose, sensor, args.dwell_s, &rng),
                            &error);
      }
    }
    const Estimate e = calibrator.solve();
    if (!e.ok) {
      ++failed;
      continue;
    }
    ++ok;
    solve_time += e.solve_time_s;
    const Eigen::VectorXd err = e.theta - truth;
    sum_sq_err += err.cwiseAbs2();
    sum_var += e.sigma.cwiseAbs2();
    const Eigen::VectorXd z = err.cwiseQuotient(e.sigma);
    sum_z += z;
    sum_z2 += z.cwiseAbs2();
  }
  nlohmann::json rows = nlohmann::json::array();
  if (!args.json) {
    fmt::print(
        "Monte Carlo: {} runs of {} ({} class, {} poses, {} design, {:.1f} s dwell, {} noise, seed "
        "{}); {} solved, {} failed; mean solve {:.2f} ms\n\n",
        args.runs, args.model, sensor.name, poses.size(), args.design, args.dwell_s, args.noise,
        args.seed, ok, failed, ok ? 1e3 * solve_time / ok : 0.0);
    fmt::print("| param | RMSE | mean CR sigma | RMSE / sigma | mean z | std z | verdict |\n");
    fmt::print("|---|---|---|---|---|---|---|\n");
  }
  int bad = 0;
  for (int i = 0; i < N; ++i) {
    const double rmse = std::sqrt(sum_sq_err[i] / ok);
    const double sigma = std::sqrt(sum_var[i] / ok);
    const double mean_z = sum_z[i] / ok;
    const double std_z = std::sqrt(std::max(0.0, sum_z2[i] / ok - mean_z * mean_z));
    const bool honest = rmse <= 1.1 * sigma && std_z >= 0.9 && std_z <= 1.1;
    bad += !honest;
    const auto& p = model->parameters()[i];
    if (args.json) {
      rows.push_back({{"name", p.name},
                      {"rmse", rmse},
                      {"sigma", sigma},
                      {"mean_z", mean_z},
                      {"std_z", std_z},
                      {"honest", honest}});
    } else {
      fmt::print("| {} | {:.3g} | {:.3g} | {:.3f} | {:+.3f} | {:.3f} | {} |\n", p.name, rmse, sigma,
                 rmse / sigma, mean_z, std_z, honest ? "ok" : "NOT HONEST");
    }
  }
  if (args.json) {
    fmt::print("{}\n", nlohmann::json{{"model", args.model},
                                      {"class", sensor.name},
                                      {"runs", args.runs},
                                      {"solved", ok},
                                      {"poses", poses.size()},
                                      {"params", rows}}
                           .dump());
  } else {
    fmt::print(
        "\nCriteria: RMSE <= 1.1 x sigma and std z in [0.9, 1.1]; {} of {} parameters fail.\n", bad,
        N);
  }
  return bad == 0 && failed == 0 ? 0 : 1;
}

}  // namespace

void AddSimFitCommands(CLI::App* app) {
  auto fit_args = std::make_shared<SimArgs>();
  auto* fit = app->add_subcommand(
      "fit-sim",
      "simulate one calibration session in memory, calibrate, print the parameter table");
  AddSimOptions(fit, fit_args.get());
  fit->callback([fit_args] { throw CLI::RuntimeError(RunFit(*fit_args)); });

  auto mc_args = std::make_shared<SimArgs>();
  mc_args->poses = 60;
  mc_args->design = "random";
  auto* mc = app->add_subcommand(
      "montecarlo", "repeat simulated sessions and check the reported sigma against the errors");
  AddSimOptions(mc, mc_args.get());
  mc->add_option("--noise", mc_args->noise,
                 "white: pose means with white noise and independent pose offsets; session: the "
                 "session simulator's full noise model (turncal sim), 100 Hz")
      ->check(CLI::IsMember({"white", "session"}))
      ->capture_default_str();
  mc->add_option("--drift-model", mc_args->drift_model,
                 "with --noise session, the calibrator's model of the bias instability: "
                 "gauss-markov (a process in time, generalised least squares) | independent (an "
                 "independent offset per pose, the model before issue 19)")
      ->check(CLI::IsMember({"gauss-markov", "independent"}))
      ->capture_default_str();
  mc->add_flag("--shuffle", mc_args->shuffle, "the design's poses in a random order");
  mc->add_option("--runs", mc_args->runs, "number of sessions")
      ->check(CLI::Range(2, 1000000))
      ->capture_default_str();
  auto pipe = std::make_shared<PipelineMonteCarloArgs>();
  auto pipeline = std::make_shared<bool>(false);
  mc->add_flag("--pipeline", *pipeline,
               "through the whole pipeline: each run a session as bytes (turncal sim), replayed "
               "through the station as turncald --replay --once does, with only --model "
               "configured (options below; --poses, --design and --noise do not apply)");
  mc->add_option("--protocol", pipe->protocol, "with --pipeline: mip | gx2 | xbus | xbus-legacy")
      ->check(CLI::IsMember({"mip", "gx2", "xbus", "xbus-legacy"}))
      ->capture_default_str();
  mc->add_option("--plan", pipe->plan,
                 "with --pipeline: default (26 cube directions in loop order + 10) | shuffled "
                 "(the same poses, a new order each run) | planner (the D-optimal plan to the "
                 "gate; a gyro model's with the rate segments and moves of --gyro-sources)")
      ->check(CLI::IsMember({"default", "shuffled", "planner"}))
      ->capture_default_str();
  mc->add_option("--gyro-sources", pipe->gyro_sources,
                 "with --pipeline and a gyro model: mixed (the plan's static poses and the "
                 "default rate segments, interleaved; no moves) | rates (the rate segments "
                 "alone) | moves (the static poses and the moves between them) | all (the "
                 "static poses with their moves, then the rate segments)")
      ->check(CLI::IsMember({"mixed", "rates", "moves", "all"}))
      ->capture_default_str();
  mc->add_option("--table-rate", pipe->table_rate_dps,
                 "with --pipeline: the simulated table moves at this rate, deg/s, and the planner "
                 "plans for it (default: every move takes 3 s)")
      ->check(CLI::PositiveNumber);
  mc->add_option("--table-accel", pipe->table_accel_dps2,
                 "with --pipeline and --table-rate: the table's angular acceleration, deg/s^2")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  mc->add_option("--planner-objective", pipe->planner_objective,
                 "with --plan planner: minimise table time or poses")
      ->check(CLI::IsMember({"time", "poses"}))
      ->capture_default_str();
  mc->add_option("--planner-drift", pipe->planner_drift,
                 "with --plan planner: plan with the class's drift model or independent poses "
                 "(the planner before issue 19)")
      ->check(CLI::IsMember({"gauss-markov", "independent"}))
      ->capture_default_str();
  mc->add_option("--jobs", pipe->jobs, "with --pipeline: runs in parallel")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  mc->add_option("--warmup", pipe->warmup,
                 "with --pipeline: warm-up transient of every triad (a gyro model's too), 1 sigma "
                 "at power-on in units of the class's bias instability (0: none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  mc->add_option("--warmup-tau", pipe->warmup_tau_s, "with --pipeline: warm-up time constant, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  mc->add_option("--random-walk", pipe->random_walk,
                 "with --pipeline: bias random walk of both triads, in units of the class's bias "
                 "instability per sqrt(100 s) (0: none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  mc->add_option("--lever-arm", pipe->lever_arm_m,
                 "with --pipeline: the IMU's offset from the table's centre, X Y Z in the table's "
                 "inner frame, m (default none)")
      ->expected(3);
  mc->add_option("--station-warmup", pipe->station_warmup,
                 "with --pipeline: the station's warm-up allowance ([station] warmup, in bias "
                 "instabilities, with --warmup-tau); default none");
  mc->add_flag("--independent", pipe->independent,
               "with --pipeline: the station's model before issue 19 (an independent offset per "
               "pose; [station] drift_model = \"independent\"), for comparisons");
  mc->add_option("--at", pipe->at,
                 "with --pipeline: judge the estimate at the end of the plan (end) or the "
                 "calibration the gate first activated (first-gate)")
      ->check(CLI::IsMember({"end", "first-gate"}))
      ->capture_default_str();
  mc->add_option("--drift-scale", pipe->drift_scale,
                 "with --pipeline: the simulated bias instability in units of the class's (the "
                 "station's prior stays the class's)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  mc->add_flag(
      "--no-identify", [pipe](std::int64_t) { pipe->identify_drift = false; },
      "with --pipeline: the station does not identify the drift's strength ([station] "
      "identify_drift = false)");
  mc->add_option("--gate-min-dof", pipe->gate_min_dof,
                 "with --pipeline: the gate's least number of redundant equations (default 3)")
      ->check(CLI::Range(0, 1000));
  mc->add_option(
      "--runs-out", pipe->runs_out,
      "with --pipeline: one JSON line per run (seed, z per parameter, chi^2 p-value, "
      "the gate and its reasons, the poses the sequencer rejected and why) to this file");
  mc->add_option("--keep", pipe->keep_dir,
                 "with --pipeline: keep the captures of runs with a parameter beyond 4 sigma in "
                 "this folder (run-SEED.tcap), for turncald --replay");
  mc->callback([mc_args, pipe, pipeline] {
    if (*pipeline) {
      pipe->model = mc_args->model;
      pipe->sensor_class = mc_args->sensor_class;
      pipe->runs = mc_args->runs;
      pipe->seed = mc_args->seed;
      pipe->dwell_s = mc_args->dwell_s;
      pipe->json = mc_args->json;
      throw CLI::RuntimeError(RunPipelineMonteCarlo(*pipe));
    }
    throw CLI::RuntimeError(RunMonteCarlo(*mc_args));
  });
}

}  // namespace turncal::tools
