#include "tools/plan_compare_command.h"

#include <fmt/format.h>

#include <algorithm>
#include <nlohmann/json.hpp>

#include "core/simulated_session.h"

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
};

struct Tally {
  std::vector<int> counts;  // -1: the gate never passed
  int failures() const { return static_cast<int>(std::count(counts.begin(), counts.end(), -1)); }
  double mean() const {
    double sum = 0;
    int n = 0;
    for (int c : counts)
      if (c > 0) sum += c, ++n;
    return n ? sum / n : 0.0;
  }
};

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
  GateTolerancesForClass(args.sensor_class, &gate.tolerances);
  Tally cube, planned;
  int planned_fewer = 0, equal = 0;
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
    const SessionOutcome b = RunSimulatedSession(
        *model, truth, sensor, options, gate, args.dwell_s, args.max_poses,
        PlannedSequence(*model, options, gate, args.dwell_s, PlannerOptions{}), &rng_b);
    cube.counts.push_back(a.poses_to_gate);
    planned.counts.push_back(b.poses_to_gate);
    const int ca = a.poses_to_gate < 0 ? 1000 : a.poses_to_gate;
    const int cb = b.poses_to_gate < 0 ? 1000 : b.poses_to_gate;
    planned_fewer += cb < ca;
    equal += cb == ca;
    runs.push_back({{"run", run}, {"cube", a.poses_to_gate}, {"planned", b.poses_to_gate}});
    if (!args.json) {
      fmt::print("run {:>3}: cube {:>3}   planned {:>3}{}\n", run, a.poses_to_gate, b.poses_to_gate,
                 b.poses_to_gate < 0 && !b.last_gate.reasons.empty()
                     ? "   (" + b.last_gate.reasons.front() + ")"
                     : "");
    }
  }
  if (args.json) {
    fmt::print("{}\n", nlohmann::json{{"model", args.model},
                                      {"class", args.sensor_class},
                                      {"runs", runs},
                                      {"cube_mean", cube.mean()},
                                      {"cube_never", cube.failures()},
                                      {"planned_mean", planned.mean()},
                                      {"planned_never", planned.failures()},
                                      {"planned_fewer", planned_fewer},
                                      {"equal", equal}}
                           .dump());
  } else {
    fmt::print(
        "{} ({} class tolerances), {} runs: poses to pass the gate\n"
        "  cube sequence: mean {:.2f}, never within 26 poses in {} run(s)\n"
        "  planned:       mean {:.2f}, never within {} poses in {} run(s)\n"
        "  planned needed fewer poses in {} run(s), as many in {}, more in {}\n",
        args.model, args.sensor_class, args.runs, cube.mean(), cube.failures(), planned.mean(),
        args.max_poses, planned.failures(), planned_fewer, equal,
        args.runs - planned_fewer - equal);
  }
  return 0;
}

}  // namespace

void AddPlanCompareCommand(CLI::App* app) {
  auto args = std::make_shared<PlanCompareArgs>();
  auto* cmd = app->add_subcommand(
      "plan-vs-cube",
      "simulated sessions: poses the real calibrator and gate need along the 26-pose cube "
      "sequence and with next-pose planning");
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
  cmd->add_flag("--json", args->json, "one JSON object");
  cmd->callback([args] { throw CLI::RuntimeError(RunPlanCompare(*args)); });
}

}  // namespace turncal::tools
