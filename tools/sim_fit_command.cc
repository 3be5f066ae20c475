#include "tools/sim_fit_command.h"

#include <fmt/format.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "core/analysis/publish_gate.h"
#include "core/estimation/calibrator.h"
#include "core/modeling/accel_physical.h"
#include "montecarlo/calibrator_montecarlo.h"
#include "protocol/observability_json.h"
#include "sim/synthetic.h"
#include "tools/help_text.h"
#include "tools/pipeline_montecarlo_command.h"
#include "tools/thermal_montecarlo_command.h"

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
  double rate_hz = 100.0;                    // montecarlo --noise session: the output rate
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

// The model and sensor class the arguments name; nullptr (with the error printed) when unknown.
std::unique_ptr<MeasurementModel> LoadModel(const SimArgs& args, const char* command,
                                            SensorClass* sensor) {
  SensorClassByName(args.sensor_class, sensor);  // CLI11 already restricted the name
  std::string error;
  auto model = MakeModel(args.model, ModelContext{}, &error);
  if (!model) fmt::print(stderr, "turncal {}: {}\n", command, error);
  return model;
}

// The codes RunFit returns. No estimate is a result, printed (in JSON with "ok": false), not a
// mistake: 1, as `free` and `montecarlo` give it.
constexpr Manual kFitSimManual = {
    "Simulates one calibration session in memory, calibrates it and prints every parameter "
    "with its 1 sigma, the truth and the error in sigma units.",
    "turncal fit-sim --model accel13 --poses 26 --design cube\n"
    "turncal fit-sim --model mag22 --class consumer --seed 7 --json",
    "0 an estimate; 1 no estimate (too few poses for the model; the calibrator's reason is "
    "printed); 2 an unknown model, a pose the calibrator refuses, or a command-line "
    "mistake",
    "docs/ACCURACY.md"};

int RunFit(const SimArgs& args) {
  SensorClass sensor;
  auto model = LoadModel(args, "fit-sim", &sensor);
  if (!model) return 2;
  std::string error;
  std::mt19937_64 rng(args.seed);
  const Eigen::VectorXd truth = DrawTruth(*model, sensor, &rng);
  Calibrator calibrator(OptionsForClass(*model, sensor));
  for (const auto& pose : montecarlo::DesignPoses(args.design, args.poses, &rng)) {
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

// The codes RunMonteCarlo and RunPipelineMonteCarloCommand return.
constexpr Manual kMonteCarloManual = {
    "Repeats simulated sessions and checks that the reported sigma matches the scatter of the "
    "errors (the honesty of the uncertainty).",
    "turncal montecarlo --model accel13 --runs 1000\n"
    "turncal montecarlo --model mag13 --noise session --runs 200\n"
    "turncal montecarlo --pipeline --model accel13 --class consumer --protocol xbus --plan "
    "shuffled --runs 200   # sessions as bytes through the station, as turncald --replay "
    "--once runs them\n"
    "turncal montecarlo --thermal -20,5,25,45,70 --model accel13 --class consumer --runs 200"
    "   # calibration over temperature, in memory\n"
    "turncal montecarlo --pipeline --model mag13 --class consumer --chamber \"0; ramp 40 4 300\" "
    "--device-rate 100 --dwell 4 --runs 200   # over temperature through the station (MODEL@T)",
    "0 every criterion holds; 1 one does not (a parameter's std z outside [0.9, 1.1] or "
    "|mean z| > 0.15, chi^2 p-values not uniform, a run without an estimate); 2 a "
    "command-line mistake",
    "docs/ACCURACY.md"};

// The calibrator alone (montecarlo/calibrator_montecarlo.h): 0 when every parameter is honest
// and every run solved, 1 otherwise, 2 on an unknown model.
int RunMonteCarlo(const SimArgs& args) {
  montecarlo::CalibratorMonteCarloOptions o;
  o.model = args.model;
  o.sensor_class = args.sensor_class;
  o.poses = args.poses;
  o.design = args.design;
  o.shuffle = args.shuffle;
  o.dwell_s = args.dwell_s;
  o.seed = args.seed;
  o.runs = args.runs;
  o.noise = args.noise;
  o.drift_model = args.drift_model;
  o.rate_hz = args.rate_hz;
  const montecarlo::CalibratorMonteCarloSummary s = montecarlo::RunCalibratorMonteCarlo(o);
  if (!s.error.empty()) {
    fmt::print(stderr, "turncal montecarlo: {}\n", s.error);
    return 2;
  }
  const Eigen::VectorXd mean_z = s.z.Mean(), std_z = s.z.Std();
  nlohmann::json rows = nlohmann::json::array();
  if (!args.json) {
    fmt::print(
        "Monte Carlo: {} runs of {} ({} class, {} poses, {} design, {:.1f} s dwell, {} noise{}, "
        "seed {}); {} solved, {} failed; mean solve {:.2f} ms\n\n",
        args.runs, args.model, s.sensor_class, s.poses, args.design, args.dwell_s, args.noise,
        args.noise == "session" ? fmt::format(" at {:g} Hz", args.rate_hz) : "", args.seed,
        s.solved, s.failed, s.mean_solve_ms);
    fmt::print("| param | RMSE | mean CR sigma | RMSE / sigma | mean z | std z | verdict |\n");
    fmt::print("|---|---|---|---|---|---|---|\n");
  }
  int bad = 0;
  for (int i = 0; i < static_cast<int>(s.parameters.size()); ++i) {
    const bool honest = s.Honest(i);
    bad += !honest;
    if (args.json) {
      rows.push_back({{"name", s.parameters[i]},
                      {"rmse", s.rmse[i]},
                      {"sigma", s.sigma[i]},
                      {"mean_z", mean_z[i]},
                      {"std_z", std_z[i]},
                      {"honest", honest}});
    } else {
      fmt::print("| {} | {:.3g} | {:.3g} | {:.3f} | {:+.3f} | {:.3f} | {} |\n", s.parameters[i],
                 s.rmse[i], s.sigma[i], s.rmse[i] / s.sigma[i], mean_z[i], std_z[i],
                 honest ? "ok" : "NOT HONEST");
    }
  }
  if (args.json) {
    fmt::print("{}\n", nlohmann::json{{"model", args.model},
                                      {"class", s.sensor_class},
                                      {"runs", args.runs},
                                      {"solved", s.solved},
                                      {"poses", s.poses},
                                      {"chi2_ks_p", s.ks.p},
                                      {"params", rows}}
                           .dump());
  } else {
    fmt::print(
        "\nchi^2 p-values against uniform: Kolmogorov-Smirnov D = {:.3f}, p = {:.3g} (reported, "
        "not a criterion here)\n",
        s.ks.d, s.ks.p);
    fmt::print("Criteria: RMSE <= 1.1 x sigma and std z in [0.9, 1.1]; {} of {} parameters fail.\n",
               bad, s.parameters.size());
  }
  return s.Passed() ? 0 : 1;
}

}  // namespace

void AddSimFitCommands(CLI::App* app) {
  auto fit_args = std::make_shared<SimArgs>();
  auto* fit = app->add_subcommand(
      "fit-sim",
      "simulate one calibration session in memory, calibrate, print the parameter table");
  AddSimOptions(fit, fit_args.get());
  fit->callback([fit_args] { throw CLI::RuntimeError(RunFit(*fit_args)); });
  SetManual(fit, kFitSimManual);

  auto mc_args = std::make_shared<SimArgs>();
  mc_args->poses = 60;
  mc_args->design = "random";
  auto* mc = app->add_subcommand(
      "montecarlo", "repeat simulated sessions and check the reported sigma against the errors");
  AddSimOptions(mc, mc_args.get());
  mc->add_option("--noise", mc_args->noise,
                 "white: pose means with white noise and independent pose offsets; session: the "
                 "session simulator's full noise model (turncal sim), 100 Hz unless --device-rate")
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
  AddPipelineMonteCarloOptions(mc, pipe.get());
  auto thermal = std::make_shared<ThermalMonteCarloArgs>();
  AddThermalMonteCarloOptions(mc, thermal.get());
  mc->callback([mc_args, pipe, pipeline, thermal] {
    // The options every engine shares, from the montecarlo command's own.
    const auto shared = [&mc_args](auto* engine, bool* json) {
      engine->model = mc_args->model;
      engine->sensor_class = mc_args->sensor_class;
      engine->runs = mc_args->runs;
      engine->seed = mc_args->seed;
      engine->dwell_s = mc_args->dwell_s;
      *json = mc_args->json;
    };
    if (!pipe->engine.chamber.empty() && !*pipeline) {
      fmt::print(stderr, "turncal montecarlo: --chamber needs --pipeline\n");
      throw CLI::RuntimeError(2);
    }
    if (!thermal->soaks_c.empty()) {
      if (*pipeline) {
        fmt::print(stderr, "turncal montecarlo: --thermal runs in memory; not with --pipeline\n");
        throw CLI::RuntimeError(2);
      }
      shared(&thermal->engine, &thermal->json);
      throw CLI::RuntimeError(RunThermalMonteCarloCommand(*thermal));
    }
    if (*pipeline) {
      shared(&pipe->engine, &pipe->json);
      // In a chamber the thermal options apply to the pipeline's calibration over temperature.
      pipe->engine.held_out_c = thermal->held_out_c;
      pipe->engine.thermal_orders = thermal->engine.orders;
      throw CLI::RuntimeError(RunPipelineMonteCarloCommand(*pipe));
    }
    if (!*pipeline && pipe->engine.rate_hz > 0) {
      if (mc_args->noise != "session") {
        fmt::print(stderr,
                   "turncal montecarlo: --device-rate applies to --pipeline and --noise session\n");
        throw CLI::RuntimeError(2);
      }
      mc_args->rate_hz = pipe->engine.rate_hz;
    }
    throw CLI::RuntimeError(RunMonteCarlo(*mc_args));
  });
  SetManual(mc, kMonteCarloManual);
}

}  // namespace turncal::tools
