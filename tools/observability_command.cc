#include "tools/observability_command.h"

#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/analysis/observability.h"
#include "core/analysis/publish_gate.h"
#include "core/frames/units.h"
#include "core/planning/pose_planner.h"
#include "montecarlo/nominal_target.h"
#include "protocol/observability_json.h"
#include "protocol/pose_file.h"
#include "sim/synthetic.h"
#include "tools/help_text.h"

namespace turncal::tools {

namespace {

struct ObservabilityArgs {
  std::vector<std::string> models = {"accel13"};
  bool structural = false;
  std::string poses_file;
  std::string sensor_class = "industrial";
  std::string point = "auto";
  double dwell_s = 5.0;
  std::uint64_t seed = 1;
  bool json = false;
  // plan
  std::string phi = "-180:150:30", gamma = "-90:90:30", psi = "-180:135:45";
  int horizon = 60;
  int top = 5;
  bool accept_gauge = false;
  double table_rate_dps = TableMotion{}.rate_dps[0];
  double table_accel_dps2 = TableMotion{}.accel_dps2[0];
  double settle_s = TableMotion{}.settle_s;
  std::string objective = "time";
  std::string drift_model = "gauss-markov";
  double rate_hz = 100.0;         // samples per second (the magnetometer's noise per pose mean)
  int min_poses = 0;              // plan at least this many poses, past the predicted gate
  std::vector<double> rates_dps;  // rate segments the table can hold (a gyroscope's candidates)
  bool no_moves = false;          // credit no move between static poses to a gyroscope
};

void AddCommonOptions(CLI::App* cmd, ObservabilityArgs* args) {
  cmd->add_option("--class", args->sensor_class,
                  "sensor class for noise, typical parameters and default tolerances "
                  "(SENSORS.md): industrial|consumer")
      ->check(CLI::IsMember({"industrial", "consumer"}))
      ->capture_default_str();
  cmd->add_option("--dwell", args->dwell_s, "seconds averaged per pose")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--point", args->point,
                  "parameter point: nominal | typical (drawn for the class) | generic (10 % "
                  "perturbation); auto = generic for --structural, typical otherwise")
      ->check(CLI::IsMember({"auto", "nominal", "typical", "generic"}))
      ->capture_default_str();
  cmd->add_option("--seed", args->seed, "random seed of the parameter point")
      ->capture_default_str();
  cmd->add_flag("--json", args->json, "one JSON object on standard output");
}

bool ReadPoses(const std::string& path, std::vector<TablePose>* poses, const char* command) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    fmt::print(stderr, "turncal {}: cannot open '{}'\n", command, path);
    return false;
  }
  std::stringstream text;
  text << in.rdbuf();
  std::string error;
  if (!ParsePoses(text.str(), poses, &error)) {
    fmt::print(stderr, "turncal {}: {}: {}\n", command, path, error);
    return false;
  }
  return true;
}

Eigen::VectorXd Point(const MeasurementModel& model, const ObservabilityArgs& args,
                      const SensorClass& sensor, bool structural) {
  std::mt19937_64 rng(args.seed);
  const std::string point =
      args.point == "auto" ? (structural ? "generic" : "typical") : args.point;
  if (point == "nominal") return model.nominal();
  if (point == "generic") return GenericParameterPoint(model, &rng);
  return DrawTruth(model, sensor, &rng);
}

std::string PointName(const ObservabilityArgs& args, bool structural) {
  const std::string point =
      args.point == "auto" ? (structural ? "generic" : "typical") : args.point;
  return point == "nominal" ? "the nominal parameters"
                            : fmt::format("a {} parameter point (seed {})", point, args.seed);
}

Eigen::Matrix3d ExpectedWeight(const MeasurementModel& model, const SensorClass& sensor,
                               double dwell_s) {
  const CalibratorOptions o = OptionsForClass(model, sensor);
  return ExpectedSqrtInformation(o.noise_density, o.pose_offset_sigma, dwell_s);
}

void PrintDirections(const char* title, const std::vector<NamedDirection>& list) {
  for (const auto& d : list) {
    fmt::print("  {} (relative singular value {:.2g}): {}\n", title, d.relative_singular_value,
               d.text);
  }
}

// The codes RunStructural, RunData and the observability command's callback return.
constexpr Manual kObservabilityManual = {
    "Rank, null directions (in parameter names) and Cramer-Rao sigma of a model: the paper's "
    "structural test, or the data-level test over a pose list.",
    "turncal observability --model mag22 --structural\n"
    "turncal observability --model accel13 --poses cube.csv --json",
    "0; 2 a command-line mistake or an unreadable pose list", "docs/OBSERVABILITY.md"};

int RunStructural(const MeasurementModel& model, const ObservabilityArgs& args,
                  const SensorClass& sensor) {
  ObservabilityOptions options;
  const StructuralReport r = AnalyzeStructure(model, Point(model, args, sensor, true), options);
  if (args.json) {
    fmt::print("{}\n", ToJson(r, model).dump());
    return 0;
  }
  fmt::print(
      "{}: structural test (the seed's): Jacobian of theta -> theta^e, {} x {}, at {}\n"
      "  rank {} of {}, condition {:.3g} (columns scaled by nominal size)\n",
      r.model, r.extended, r.params, PointName(args, true), r.analysis.rank, r.params,
      r.analysis.condition);
  PrintDirections("null direction", r.analysis.null);
  PrintDirections("weak direction", r.analysis.weak);
  return 0;
}

int RunData(const MeasurementModel& model, const ObservabilityArgs& args,
            const SensorClass& sensor) {
  std::vector<TablePose> poses;
  if (!ReadPoses(args.poses_file, &poses, "observability")) return 2;
  const Eigen::Matrix3d W = ExpectedWeight(model, sensor, args.dwell_s);
  std::vector<WeightedPose> weighted;
  for (const auto& p : poses) weighted.push_back({p, Eigen::Vector3d::Zero(), W, nullptr});
  const DataReport r =
      AnalyzeData(model, Point(model, args, sensor, false), weighted, ObservabilityOptions{});
  GateOptions gate;
  GateDefaultsForClass(args.sensor_class, &gate);
  const std::vector<std::string> shortfalls = PrecisionShortfalls(model, r.sigma, gate);
  if (args.json) {
    nlohmann::json j = ToJson(r, model);
    j["class"] = args.sensor_class;
    j["dwell_s"] = args.dwell_s;
    j["predicted_precision"] = {{"pass", shortfalls.empty()}, {"shortfalls", shortfalls}};
    fmt::print("{}\n", j.dump());
    return 0;
  }
  fmt::print(
      "{}: data-level test over {} poses ({} class noise, {} s dwell) at {}\n"
      "  rank {} of {} (identifiable: {}), condition {:.3g} (columns scaled by nominal size)\n",
      r.model, r.poses, args.sensor_class, args.dwell_s, PointName(args, false), r.analysis.rank,
      r.params, r.expected_rank, r.analysis.condition);
  if (!r.gauge.empty()) fmt::print("  sigma in the gauge: {}\n", r.gauge);
  const PoseDiversity& d = r.diversity;
  fmt::print(
      "  pose diversity: linear-form regressor rank {} of 10 (smallest singular value {:.3g}), "
      "{} distinct down directions\n",
      d.regressor_rank, d.regressor_min_singular, d.distinct_down);
  for (const auto& f : d.findings) fmt::print("  poses: {}\n", f);
  PrintDirections("null direction", r.analysis.null);
  PrintDirections("weak direction", r.analysis.weak);
  fmt::print("  Cramer-Rao 1 sigma:\n");
  const auto gated = GatedParameters(model);
  for (int i = 0; i < model.num_parameters(); ++i) {
    const ParameterInfo& p = model.parameters()[i];
    const bool is_gated = std::find(gated.begin(), gated.end(), i) != gated.end();
    fmt::print("    {:<8} {:>12}  {}\n", p.name, FormatSigma(p, r.sigma[i]),
               is_gated ? fmt::format("tolerance {}{}", FormatSigma(p, ToleranceFor(p, gate)),
                                      r.sigma[i] <= ToleranceFor(p, gate) ? "" : "  NOT MET")
                        : std::string(ToString(p.kind)) + ", not gated");
  }
  fmt::print("  predicted precision for the gate ({} tolerances): {}\n", args.sensor_class,
             shortfalls.empty() ? "met" : fmt::format("{} shortfall(s)", shortfalls.size()));
  return 0;
}

bool ParseRange(const std::string& text, AxisRange* out) {
  double a = 0, b = 0, c = 0;
  char s1 = 0, s2 = 0;
  std::istringstream in(text);
  if (!(in >> a >> s1 >> b >> s2 >> c) || s1 != ':' || s2 != ':') {
    std::istringstream single(text);
    if (!(single >> a) || !single.eof()) return false;
    *out = AxisRange{a, a, 0.0};
    return true;
  }
  std::string rest;
  if (in >> rest) return false;
  *out = AxisRange{a, b, c};
  return true;
}

// The codes RunPlan returns.
constexpr Manual kPlanManual = {
    "The D-optimal next pose over a grid of reachable table angles, and the greedy plan until "
    "the predicted publish gate passes.",
    "turncal plan --model accel13 --model mag13\n"
    "turncal plan --poses captured.csv --gamma -60:60:30 --json",
    "0 a plan (also when the gate is not predicted within the horizon); 2 a command-line "
    "mistake, an unreadable pose list, or options the planner refuses (too many candidate poses "
    "or rate segments)",
    "docs/OBSERVABILITY.md"};

int RunPlan(const ObservabilityArgs& args) {
  SensorClass sensor;
  SensorClassByName(args.sensor_class, &sensor);
  PlannerOptions options;
  options.horizon = args.horizon;
  options.top = args.top;
  options.dwell_s = args.dwell_s;
  options.min_continuation = args.min_poses;
  options.motion.rate_dps.setConstant(args.table_rate_dps);
  options.motion.accel_dps2.setConstant(args.table_accel_dps2);
  options.motion.settle_s = args.settle_s;
  options.objective = args.objective == "poses" ? PlanObjective::kPoses : PlanObjective::kTime;
  options.rates.rates_dps = args.rates_dps;
  options.moves = !args.no_moves;
  if (!ParseRange(args.phi, &options.grid.phi) || !ParseRange(args.gamma, &options.grid.gamma) ||
      !ParseRange(args.psi, &options.grid.psi)) {
    fmt::print(stderr, "turncal plan: a range is MIN:MAX:STEP in degrees, or one angle\n");
    return 2;
  }
  std::string error;
  if (!options.IsValid(&error)) {
    fmt::print(stderr, "turncal plan: {}\n", error);
    return 2;
  }
  std::vector<TablePose> captured;
  if (!args.poses_file.empty() && !ReadPoses(args.poses_file, &captured, "plan")) return 2;
  std::vector<std::unique_ptr<MeasurementModel>> models;
  std::vector<PlanningTarget> targets;
  for (const auto& name : args.models) {
    auto model = MakeModel(name, ModelContext{}, &error);
    if (!model) {
      fmt::print(stderr, "turncal plan: {}\n", error);
      return 2;
    }
    PlanningTarget t = montecarlo::NominalPlanningTarget(
        *model, sensor, args.drift_model != "independent", args.dwell_s, args.rate_hz);
    t.theta = Point(*model, args, sensor, false);
    // The captured poses as if taken in the file's order from home at the table's rates.
    for (const auto& p : captured)
      t.captured.push_back({p, Eigen::Vector3d::Zero(), t.sqrt_information, nullptr});
    if (t.drift.enabled()) t.captured_windows = options.motion.DwellWindows(captured, args.dwell_s);
    t.gate.accept_gauge_dependent_correction = args.accept_gauge;
    targets.push_back(t);
    models.push_back(std::move(model));
  }
  const NextPoseAdvice a = PlanNextPose(targets, options);
  // The planner refuses only what the options ask (a grid or a rate list with too many
  // candidates): a mistake, 2, as the ranges it checks above (kPlanManual).
  if (args.json) {
    fmt::print("{}\n", ToJson(a).dump());
    return a.ok ? 0 : 2;
  }
  if (!a.ok) {
    fmt::print(stderr, "turncal plan: {}\n", a.error);
    return 2;
  }
  auto show = [](const TablePose& p) {
    if (p.is_rate()) {
      // The turning axis's own angle means nothing.
      const double held[3] = {p.phi_rad, p.gamma_rad, p.psi_rad};
      const char* names[3] = {"phi", "gamma", "psi"};
      const int turning = p.rate_axis == TableAxis::kInner    ? 0
                          : p.rate_axis == TableAxis::kMiddle ? 1
                                                              : 2;
      std::string text = fmt::format("rate {:+7.1f} deg/s about {:<6}", p.rate_radps * kDegPerRad,
                                     ToString(p.rate_axis));
      for (int i = 0; i < 3; ++i) {
        if (i != turning) text += fmt::format("  {} {:6.1f}", names[i], held[i] * kDegPerRad);
      }
      return text;
    }
    return fmt::format("phi {:7.1f}  gamma {:6.1f}  psi {:7.1f}", p.phi_rad * kDegPerRad,
                       p.gamma_rad * kDegPerRad, p.psi_rad * kDegPerRad);
  };
  std::string names;
  for (const auto& m : args.models) names += (names.empty() ? "" : "+") + m;
  fmt::print("{}: {} poses captured, {} candidates, {} class tolerances\n", names, captured.size(),
             a.candidates, args.sensor_class);
  fmt::print(
      "planning for {} ({}), {} drift model; table {:g} deg/s, {:g} deg/s^2, settle {:g} s, "
      "dwell {:g} s\n",
      args.objective == "poses" ? "the fewest poses" : "the least table time",
      args.objective == "poses" ? "log det F gain per pose" : "log det F gain per second",
      a.drift_aware ? "with the" : "without a", args.table_rate_dps, args.table_accel_dps2,
      args.settle_s, args.dwell_s);
  fmt::print("next pose: {}   (log det F gains {:.3f} in {:.1f} s)\n", show(a.pose), a.gain,
             a.seconds);
  for (const auto& c : a.top) {
    fmt::print("  candidate {}   gain {:.3f} in {:5.1f} s\n", show(c.pose), c.gain, c.seconds);
  }
  for (const auto& m : a.models) {
    if (m.gauge_blocks) {
      fmt::print(
          "  {}: the correction rests on a gauge direction; the gate will not pass without "
          "--accept-gauge\n",
          m.model);
    }
    fmt::print("  {} after this pose: {}\n", m.model,
               m.shortfalls_after.empty()
                   ? "precision met"
                   : fmt::format("{} shortfall(s), e.g. {}", m.shortfalls_after.size(),
                                 m.shortfalls_after.front()));
  }
  const bool blocked = std::any_of(a.models.begin(), a.models.end(),
                                   [](const ModelOutlook& m) { return m.gauge_blocks; });
  if (blocked) {
    fmt::print("the gate cannot pass while a correction rests on a gauge direction\n");
  } else if (a.poses_to_gate == 0) {
    fmt::print("the captured poses already meet the predicted gate\n");
  } else if (a.poses_to_gate > 0) {
    const bool rates = std::any_of(a.continuation.begin(), a.continuation.end(),
                                   [](const TablePose& p) { return p.is_rate(); });
    fmt::print("predicted to the gate: {} {}, {:.0f} s of table time (greedy plan below)\n",
               a.poses_to_gate, rates ? "steps (poses and rate segments)" : "poses",
               a.seconds_to_gate);
    for (const auto& m : a.models) {
      if (m.planned_rate_segments + m.planned_moves + m.captured_rate_segments + m.captured_moves ==
          0)
        continue;
      fmt::print(
          "  {}: {} static poses, {} rate segments and {} moves captured; the plan adds {}, {} and "
          "{}\n",
          m.model, m.captured_poses, m.captured_rate_segments, m.captured_moves, m.planned_poses,
          m.planned_rate_segments, m.planned_moves);
    }
  } else {
    fmt::print("the gate is not predicted within {} more poses\n", options.horizon);
  }
  for (std::size_t i = 0; i < a.continuation.size(); ++i) {
    fmt::print("  {:>3}: {}   {:5.1f} s\n", captured.size() + i + 1, show(a.continuation[i]),
               a.continuation_seconds[i]);
  }
  return 0;
}

constexpr Manual kPosesManual = {
    "Prints a pose list (CSV, degrees) of a standard design, for --poses FILE of the other "
    "commands and for a controller script.",
    "turncal poses --design cube > cube.csv\nturncal poses --design random --count 40 --seed 3",
    "0; 2 a command-line mistake", "docs/OBSERVABILITY.md"};

int RunPoses(const std::string& design, int count, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<TablePose> poses;
  if (design == "cube") {
    poses = CubePoses26();
    if (count > 0 && count < static_cast<int>(poses.size())) poses.resize(count);
  } else if (design == "about-z") {
    poses = AboutZPoses(count > 0 ? count : 12);
  } else {
    poses = RandomPoses(count > 0 ? count : 26, &rng);
  }
  fmt::print("# turncal poses --design {}: phi, gamma, psi in degrees\nphi,gamma,psi\n", design);
  for (const auto& p : poses) {
    fmt::print("{:.6f},{:.6f},{:.6f}\n", p.phi_rad * kDegPerRad, p.gamma_rad * kDegPerRad,
               p.psi_rad * kDegPerRad);
  }
  return 0;
}

}  // namespace

void AddObservabilityCommands(CLI::App* app) {
  auto design = std::make_shared<std::string>("cube");
  auto count = std::make_shared<int>(0);
  auto seed = std::make_shared<std::uint64_t>(1);
  auto* poses_cmd = app->add_subcommand(
      "poses", "print a pose list (CSV, degrees) of a standard design, for --poses FILE");
  poses_cmd
      ->add_option("--design", *design,
                   "cube (26 cube directions, psi cycling) | about-z (outer axis only) | random")
      ->check(CLI::IsMember({"cube", "about-z", "random"}))
      ->capture_default_str();
  poses_cmd->add_option("--count", *count, "number of poses (cube: the first N of 26)")
      ->check(CLI::Range(1, 100000));
  poses_cmd->add_option("--seed", *seed, "random seed")->capture_default_str();
  poses_cmd->callback(
      [design, count, seed] { throw CLI::RuntimeError(RunPoses(*design, *count, *seed)); });
  SetManual(poses_cmd, kPosesManual);

  auto args = std::make_shared<ObservabilityArgs>();
  auto* obs = app->add_subcommand(
      "observability",
      "rank, null directions and Cramer-Rao sigma of a model: the seed's structural test "
      "(--structural) or the data-level test over a pose list (--poses FILE)");
  obs->add_option("--model", args->models, "model (turncal models)")->required()->expected(1);
  auto* structural = obs->add_flag("--structural", args->structural,
                                   "Jacobian of theta -> theta^e (H' entries and biases)");
  auto* poses = obs->add_option("--poses", args->poses_file,
                                "pose list: JSON or CSV of phi, gamma, psi in degrees");
  structural->excludes(poses);
  AddCommonOptions(obs, args.get());
  obs->callback([args] {
    if (!args->structural && args->poses_file.empty()) {
      throw CLI::ValidationError("observability", "give --structural or --poses FILE");
    }
    std::string error;
    auto model = MakeModel(args->models.front(), ModelContext{}, &error);
    if (!model) {
      fmt::print(stderr, "turncal observability: {}\n", error);
      throw CLI::RuntimeError(2);
    }
    SensorClass sensor;
    SensorClassByName(args->sensor_class, &sensor);
    throw CLI::RuntimeError(args->structural ? RunStructural(*model, *args, sensor)
                                             : RunData(*model, *args, sensor));
  });
  SetManual(obs, kObservabilityManual);

  auto plan_args = std::make_shared<ObservabilityArgs>();
  auto* plan = app->add_subcommand(
      "plan",
      "D-optimal next pose over a grid of reachable table poses, and the greedy plan until the "
      "predicted publish gate passes");
  plan->add_option("--model", plan_args->models, "model(s) in use; repeat for several")
      ->capture_default_str();
  plan->add_option("--poses", plan_args->poses_file,
                   "poses already captured: JSON or CSV of phi, gamma, psi in degrees");
  plan->add_option("--phi", plan_args->phi, "inner axis MIN:MAX:STEP in degrees, or one angle")
      ->capture_default_str();
  plan->add_option("--gamma", plan_args->gamma, "middle axis MIN:MAX:STEP in degrees")
      ->capture_default_str();
  plan->add_option("--psi", plan_args->psi, "outer axis MIN:MAX:STEP in degrees")
      ->capture_default_str();
  plan->add_option("--horizon", plan_args->horizon, "most poses to look ahead")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  plan->add_option("--top", plan_args->top, "candidates to list")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  plan->add_flag("--accept-gauge", plan_args->accept_gauge,
                 "let mag22's gauge-dependent correction pass the gate");
  plan->add_option("--objective", plan_args->objective,
                   "minimise table time (information per second) or poses (per pose)")
      ->check(CLI::IsMember({"time", "poses"}))
      ->capture_default_str();
  plan->add_option("--table-rate", plan_args->table_rate_dps, "the table's move rate, deg/s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  plan->add_option("--table-accel", plan_args->table_accel_dps2,
                   "the table's angular acceleration, deg/s^2")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  plan->add_option("--settle", plan_args->settle_s, "seconds the table settles after a move")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  plan->add_option("--min-poses", plan_args->min_poses,
                   "plan at least this many poses, past the predicted gate (a whole session)")
      ->check(CLI::Range(0, 1000))
      ->capture_default_str();
  plan->add_option("--rate", plan_args->rate_hz, "the device's sample rate, Hz")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  plan->add_option("--drift-model", plan_args->drift_model,
                   "the class's bias drift as a process in time, or independent per pose")
      ->check(CLI::IsMember({"gauss-markov", "independent"}))
      ->capture_default_str();
  plan->add_option("--rates", plan_args->rates_dps,
                   "rates the table can hold, deg/s, comma separated (a gyroscope's rate segments; "
                   "none: no rate mode)")
      ->delimiter(',');
  plan->add_flag(
      "--no-moves", plan_args->no_moves,
      "credit a gyroscope with no move between static poses ([sequencer] moves = false)");
  AddCommonOptions(plan, plan_args.get());
  plan->callback([plan_args] { throw CLI::RuntimeError(RunPlan(*plan_args)); });
  SetManual(plan, kPlanManual);
}

}  // namespace turncal::tools
