#include "tools/plan_compare_command.h"

#include <fmt/format.h>

#include <algorithm>
#include <memory>
#include <nlohmann/json.hpp>

#include "core/frames/mount.h"
#include "sim/fixture_capture.h"
#include "sim/simulated_batch.h"
#include "sim/simulated_session.h"
#include "tools/help_text.h"

namespace turncal::tools {

namespace {

struct PlanCompareArgs {
  std::string model = "accel13";
  std::string sensor_class = "consumer";
  int runs = 20;
  int max_poses = 60;
  double dwell_s = 5.0;
  std::uint64_t seed = 1;
  bool json = false;
  double table_rate_dps = TableMotion{}.rate_dps[0];
  double table_accel_dps2 = TableMotion{}.accel_dps2[0];
  std::string objective = "time";
  int units = 0;  // > 0: a fixture of that many units (docs/BATCH.md)
};

// A fixture's units turn through four orientations (sim::kFixtureMounts): as placed, a quarter
// turn about the vertical, upside down, and on its side (the case's z along the table's y).

// Table seconds of the first `count` poses from home: moves, settling and dwells.
double SessionSeconds(const std::vector<TablePose>& poses, int count, const TableMotion& table,
                      double dwell_s) {
  if (count <= 0 || poses.empty()) return 0.0;
  const std::vector<TablePose> first(
      poses.begin(), poses.begin() + std::min<std::ptrdiff_t>(count, std::ssize(poses)));
  return table.DwellWindows(first, dwell_s).back().t1_s;
}

struct Tally {
  std::vector<int> counts;  // -1: the gate never passed
  std::vector<double> seconds;
  double mean_seconds() const {
    double sum = 0;
    int n = 0;
    for (std::size_t i = 0; i < counts.size(); ++i)
      if (counts[i] > 0) sum += seconds[i], ++n;
    return n ? sum / n : 0.0;
  }
  int failures() const { return static_cast<int>(std::count(counts.begin(), counts.end(), -1)); }
  double mean() const {
    double sum = 0;
    int n = 0;
    for (int c : counts)
      if (c > 0) sum += c, ++n;
    return n ? sum / n : 0.0;
  }
};

// The keys of --json's object both comparisons share.
nlohmann::json SummaryJson(const PlanCompareArgs& args, const nlohmann::json& runs,
                           const Tally& cube, const Tally& planned) {
  return {{"model", args.model},
          {"class", args.sensor_class},
          {"objective", args.objective},
          {"table_rate_dps", args.table_rate_dps},
          {"runs", runs},
          {"cube_mean", cube.mean()},
          {"cube_mean_s", cube.mean_seconds()},
          {"cube_never", cube.failures()},
          {"planned_mean", planned.mean()},
          {"planned_mean_s", planned.mean_seconds()},
          {"planned_never", planned.failures()}};
}

// The codes RunPlanCompare returns.
constexpr Manual kPlanVsCubeManual = {
    "Simulated sessions: how many poses the real calibrator and gate need along the 26-pose "
    "cube and with next-pose planning.",
    "turncal plan-vs-cube --model accel13 --class consumer --runs 50\n"
    "turncal plan-vs-cube --model accel13 --class industrial --units 8 --runs 20",
    "0; 2 a command-line "
    "mistake",
    "docs/OBSERVABILITY.md"};

// --units N: the batch's poses and table seconds to the last unit's gate along the cube and with
// the batch's planning, and units per hour of table time.
int RunBatchCompare(const PlanCompareArgs& args, const SensorClass& sensor, const GateOptions& gate,
                    const PlannerOptions& planner) {
  std::string error;
  std::vector<std::unique_ptr<MeasurementModel>> models;
  for (int k = 0; k < args.units; ++k) {
    ModelContext context;
    ParseMountAxes(sim::kFixtureMounts[k % 4], &context.mounting, nullptr);
    models.push_back(MakeModel(args.model, context, &error));
    if (!models.back()) {
      fmt::print(stderr, "turncal plan-vs-cube: {}\n", error);
      return 2;
    }
  }
  Tally cube, planned;
  nlohmann::json runs = nlohmann::json::array();
  for (int run = 0; run < args.runs; ++run) {
    std::vector<BatchUnit> units;
    for (int k = 0; k < args.units; ++k) {
      std::mt19937_64 truth_rng(args.seed + static_cast<std::uint64_t>(run) * 1000 +
                                static_cast<std::uint64_t>(k));
      BatchUnit u;
      u.model = models[static_cast<std::size_t>(k)].get();
      u.truth = DrawTruth(*u.model, sensor, &truth_rng);
      u.options = OptionsForClass(*u.model, sensor);
      units.push_back(u);
    }
    std::mt19937_64 rng_a(1000003 * (args.seed + static_cast<std::uint64_t>(run)));
    std::mt19937_64 rng_b = rng_a;
    const BatchOutcome a =
        RunSimulatedBatch(units, sensor, gate, args.dwell_s, 26, CubePoses26(), planner, &rng_a);
    const BatchOutcome b =
        RunSimulatedBatch(units, sensor, gate, args.dwell_s, args.max_poses, {}, planner, &rng_b);
    const double sa = SessionSeconds(a.poses, a.poses_to_last_gate, planner.motion, args.dwell_s);
    const double sb = SessionSeconds(b.poses, b.poses_to_last_gate, planner.motion, args.dwell_s);
    cube.counts.push_back(a.poses_to_last_gate);
    cube.seconds.push_back(sa);
    planned.counts.push_back(b.poses_to_last_gate);
    planned.seconds.push_back(sb);
    runs.push_back({{"run", run},
                    {"cube", a.poses_to_last_gate},
                    {"cube_s", sa},
                    {"cube_units", a.unit_poses_to_gate},
                    {"planned", b.poses_to_last_gate},
                    {"planned_s", sb},
                    {"planned_units", b.unit_poses_to_gate}});
    if (!args.json) {
      fmt::print("run {:>3}: cube {:>3} poses {:6.1f} s   planned {:>3} poses {:6.1f} s\n", run,
                 a.poses_to_last_gate, sa, b.poses_to_last_gate, sb);
    }
  }
  const auto per_hour = [&](const Tally& t) {
    return t.mean_seconds() > 0 ? 3600.0 * args.units / t.mean_seconds() : 0.0;
  };
  if (args.json) {
    nlohmann::json summary = SummaryJson(args, runs, cube, planned);
    summary["units"] = args.units;
    summary["cube_units_per_hour"] = per_hour(cube);
    summary["planned_units_per_hour"] = per_hour(planned);
    fmt::print("{}\n", summary.dump());
    return 0;
  }
  std::string mounts;
  for (int k = 0; k < std::min(args.units, 4); ++k)
    mounts += std::string(k ? ", " : "") + sim::kFixtureMounts[k];
  fmt::print(
      "{} units of {} ({} class tolerances) on one table, mounts {}, {} runs: poses and table "
      "seconds to the last unit's gate (table {:g} deg/s, {:g} deg/s^2, settle {:g} s, dwell {:g} "
      "s; planner minimises {})\n"
      "  cube sequence: mean {:.2f} poses, {:.1f} s, {:.1f} units/hour; a unit never within 26 "
      "poses in {} run(s)\n"
      "  planned:       mean {:.2f} poses, {:.1f} s, {:.1f} units/hour; never within {} poses in "
      "{} run(s)\n",
      args.units, args.model, args.sensor_class, mounts, args.runs, args.table_rate_dps,
      args.table_accel_dps2, planner.motion.settle_s, args.dwell_s, args.objective, cube.mean(),
      cube.mean_seconds(), per_hour(cube), cube.failures(), planned.mean(), planned.mean_seconds(),
      per_hour(planned), args.max_poses, planned.failures());
  return 0;
}

int RunPlanCompare(const PlanCompareArgs& args) {
  SensorClass sensor;
  SensorClassByName(args.sensor_class, &sensor);
  std::string error;
  auto model = MakeModel(args.model, ModelContext{}, &error);
  if (!model) {
    fmt::print(stderr, "turncal plan-vs-cube: {}\n", error);
    return 2;
  }
  const CalibratorOptions options = OptionsForClass(*model, sensor);
  GateOptions gate;
  GateDefaultsForClass(args.sensor_class, &gate);
  PlannerOptions planner;
  planner.dwell_s = args.dwell_s;
  planner.motion.rate_dps.setConstant(args.table_rate_dps);
  planner.motion.accel_dps2.setConstant(args.table_accel_dps2);
  planner.objective = args.objective == "poses" ? PlanObjective::kPoses : PlanObjective::kTime;
  if (args.units > 0) return RunBatchCompare(args, sensor, gate, planner);
  Tally cube, planned;
  int planned_fewer = 0, equal = 0, planned_quicker = 0;
  nlohmann::json runs = nlohmann::json::array();
  for (int run = 0; run < args.runs; ++run) {
    std::mt19937_64 truth_rng(args.seed + static_cast<std::uint64_t>(run));
    const Eigen::VectorXd truth = DrawTruth(*model, sensor, &truth_rng);
    // The same noise stream for both sequences.
    std::mt19937_64 rng_a(1000003 * (args.seed + static_cast<std::uint64_t>(run)));
    std::mt19937_64 rng_b = rng_a;
    std::vector<TablePose> design = CubePoses26();
    const SessionOutcome a =
        RunSimulatedSession(*model, truth, sensor, options, gate, args.dwell_s,
                            std::min<int>(args.max_poses, 26), FixedSequence(design), &rng_a);
    const SessionOutcome b =
        RunSimulatedSession(*model, truth, sensor, options, gate, args.dwell_s, args.max_poses,
                            PlannedSequence(*model, gate, args.dwell_s, planner), &rng_b);
    cube.counts.push_back(a.poses_to_gate);
    planned.counts.push_back(b.poses_to_gate);
    const double sa = SessionSeconds(a.poses, a.poses_to_gate, planner.motion, args.dwell_s);
    const double sb = SessionSeconds(b.poses, b.poses_to_gate, planner.motion, args.dwell_s);
    cube.seconds.push_back(sa);
    planned.seconds.push_back(sb);
    planned_quicker += b.poses_to_gate > 0 && (a.poses_to_gate < 0 || sb < sa);
    const int ca = a.poses_to_gate < 0 ? 1000 : a.poses_to_gate;
    const int cb = b.poses_to_gate < 0 ? 1000 : b.poses_to_gate;
    planned_fewer += cb < ca;
    equal += cb == ca;
    runs.push_back({{"run", run},
                    {"cube", a.poses_to_gate},
                    {"planned", b.poses_to_gate},
                    {"cube_s", sa},
                    {"planned_s", sb}});
    if (!args.json) {
      fmt::print("run {:>3}: cube {:>3} poses {:6.1f} s   planned {:>3} poses {:6.1f} s{}\n", run,
                 a.poses_to_gate, sa, b.poses_to_gate, sb,
                 b.poses_to_gate < 0 && !b.last_gate.reasons.empty()
                     ? "   (" + b.last_gate.reasons.front() + ")"
                     : "");
    }
  }
  if (args.json) {
    nlohmann::json summary = SummaryJson(args, runs, cube, planned);
    summary["planned_fewer"] = planned_fewer;
    summary["planned_quicker"] = planned_quicker;
    summary["equal"] = equal;
    fmt::print("{}\n", summary.dump());
  } else {
    fmt::print(
        "{} ({} class tolerances), {} runs: poses and table seconds to pass the gate (table {:g} "
        "deg/s, {:g} deg/s^2, settle {:g} s, dwell {:g} s; planner minimises {})\n"
        "  cube sequence: mean {:.2f} poses, {:.1f} s; never within 26 poses in {} run(s)\n"
        "  planned:       mean {:.2f} poses, {:.1f} s; never within {} poses in {} run(s)\n"
        "  planned needed fewer poses in {} run(s), as many in {}, more in {}; less time in {}\n",
        args.model, args.sensor_class, args.runs, args.table_rate_dps, args.table_accel_dps2,
        planner.motion.settle_s, args.dwell_s, args.objective, cube.mean(), cube.mean_seconds(),
        cube.failures(), planned.mean(), planned.mean_seconds(), args.max_poses, planned.failures(),
        planned_fewer, equal, args.runs - planned_fewer - equal, planned_quicker);
  }
  return 0;
}

}  // namespace

void AddPlanCompareCommand(CLI::App* app) {
  auto args = std::make_shared<PlanCompareArgs>();
  auto* cmd = app->add_subcommand(
      "plan-vs-cube",
      "simulated sessions in memory (independent pose noise; for drift and bytes use montecarlo "
      "--pipeline): poses and table seconds the real calibrator and gate need along the 26-pose "
      "cube sequence and with next-pose planning");
  SetManual(cmd, kPlanVsCubeManual);
  cmd->add_option("--model", args->model, "model (turncal models)")->capture_default_str();
  cmd->add_option("--class", args->sensor_class, "industrial|consumer (noise and tolerances)")
      ->check(CLI::IsMember({"industrial", "consumer"}))
      ->capture_default_str();
  cmd->add_option("--runs", args->runs, "sessions (truth and noise from seed + run)")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  cmd->add_option("--max-poses", args->max_poses, "give up on a planned session after this")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  cmd->add_option("--dwell", args->dwell_s, "seconds averaged per pose")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--seed", args->seed, "first seed")->capture_default_str();
  cmd->add_option("--objective", args->objective,
                  "the planner minimises table time (information per second) or poses")
      ->check(CLI::IsMember({"time", "poses"}))
      ->capture_default_str();
  cmd->add_option("--table-rate", args->table_rate_dps, "the table's move rate, deg/s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--table-accel", args->table_accel_dps2,
                  "the table's angular acceleration, deg/s^2")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--units", args->units,
                  "a fixture of this many units on one table, in four mounts in turn (as placed, "
                  "a quarter turn about the vertical, upside down, on its side): poses, seconds "
                  "and units per hour to the last unit's gate (docs/BATCH.md)")
      ->check(CLI::Range(1, 64));
  cmd->add_flag("--json", args->json, "one JSON object");
  cmd->callback([args] { throw CLI::RuntimeError(RunPlanCompare(*args)); });
}

}  // namespace turncal::tools
