#include "tools/pipeline_montecarlo_command.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "tools/z_score_table.h"

namespace turncal::tools {
namespace {

// One JSON line per run to `path`; false when it cannot be written.
bool WriteRuns(const std::string& path, const montecarlo::PipelineMonteCarloSummary& s) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) return false;
  for (const auto& r : s.runs) {
    nlohmann::json z = nlohmann::json::object();
    for (std::size_t i = 0; r.ok && i < s.parameters.size(); ++i) {
      z[s.parameters[i]] = r.z[static_cast<Eigen::Index>(i)];
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
  return true;
}

// A fixture's units (--units): each unit's mount and its parameters' rows.
nlohmann::json UnitRows(const montecarlo::PipelineMonteCarloSummary& s) {
  nlohmann::json units = nlohmann::json::array();
  for (std::size_t u = 0; u < s.unit_z.size(); ++u) {
    nlohmann::json honest = nlohmann::json::object();
    for (int i = 0; i < s.unit_z[u].parameters(); ++i) {
      honest[s.parameters[static_cast<std::size_t>(i)]] =
          montecarlo::PipelineMonteCarloSummary::UnitHonest(s.unit_z[u], i);
    }
    units.push_back({{"unit", u + 1},
                     {"mount", s.unit_mounts[u]},
                     {"runs", s.unit_z[u].runs()},
                     {"honest", honest},
                     {"params", ZScoreRows(s.parameters, s.unit_z[u], false)}});
  }
  return units;
}

// Per unit: the spread of its parameters' std z and the largest |mean z|, and how many fail.
std::string UnitLines(const montecarlo::PipelineMonteCarloSummary& s) {
  std::string out;
  for (std::size_t u = 0; u < s.unit_z.size(); ++u) {
    const auto& z = s.unit_z[u];
    std::string bad;
    for (int i = 0; i < z.parameters(); ++i) {
      if (!montecarlo::PipelineMonteCarloSummary::UnitHonest(z, i)) {
        bad += (bad.empty() ? "" : ", ") + s.parameters[static_cast<std::size_t>(i)];
      }
    }
    const double n = std::max(1, z.runs());
    const double k = montecarlo::PipelineMonteCarloSummary::kUnitHonestZ;
    out += fmt::format(
        "unit {} ({}): {} sessions, std z {:.3f}-{:.3f} (within [{:.3f}, {:.3f}]), largest "
        "|mean z| {:.3f} (within {:.3f}): {}\n",
        u + 1, s.unit_mounts[u], z.runs(), z.Std().minCoeff(), z.Std().maxCoeff(),
        1 - k / std::sqrt(2 * n), 1 + k / std::sqrt(2 * n), z.Mean().cwiseAbs().maxCoeff(),
        k / std::sqrt(n), bad.empty() ? std::string("honest") : "NOT HONEST: " + bad);
  }
  return out.empty() ? out : "\n" + out;
}

void PrintPipelineJson(const montecarlo::PipelineMonteCarloOptions& o,
                       const montecarlo::PipelineMonteCarloSummary& s) {
  fmt::print("{}\n", nlohmann::json{{"model", o.model},
                                    {"class", o.sensor_class},
                                    {"protocol", o.protocol},
                                    {"plan", o.plan},
                                    {"planner_predicted_poses", s.predicted_poses},
                                    {"gyro_sources", s.gyro ? o.gyro_sources : ""},
                                    {"planner_objective", o.planner_objective},
                                    {"planner_drift", o.planner_drift},
                                    {"table_rate_dps", o.table_rate_dps},
                                    {"warmup", o.warmup},
                                    {"random_walk", o.random_walk},
                                    {"lever_arm_m", o.lever_arm_m},
                                    {"drift_scale", o.drift_scale},
                                    {"identify_drift", o.identify_drift},
                                    {"station_warmup", o.station_warmup},
                                    {"chamber", o.chamber},
                                    {"thermal_orders", o.chamber.empty() ? "" : o.thermal_orders},
                                    {"device_rate_hz", o.rate_hz},
                                    {"mag_rate_hz", o.mag_rate_hz},
                                    {"dwell_s", o.dwell_s},
                                    {"seed", o.seed},
                                    {"runs", o.runs},
                                    {"solved", s.solved},
                                    {"poses_mean", s.poses_mean},
                                    {"gate_pass", s.gate_pass},
                                    {"independent", o.independent},
                                    {"activated", s.activated},
                                    {"poses_to_gate", s.poses_to_gate},
                                    {"poses_to_gate_max", s.poses_to_gate_max},
                                    {"seconds_to_gate", s.seconds_to_gate},
                                    {"chi2_ks_d", s.ks.d},
                                    {"chi2_ks_p", s.ks.p},
                                    {"units", o.units},
                                    {"unit_params", UnitRows(s)},
                                    {"params", ZScoreRows(s.parameters, s.z, false)}}
                         .dump());
}

// What was simulated, after the plan's name: the planner's objective, the table, the drift.
std::string PlanConditions(const montecarlo::PipelineMonteCarloOptions& o) {
  return (o.plan == "planner"
              ? fmt::format(" for {}, {} drift", o.planner_objective, o.planner_drift)
              : std::string()) +
         (o.table_rate_dps > 0 ? fmt::format(", table {:g} deg/s", o.table_rate_dps)
                               : std::string());
}

std::string DriftText(const montecarlo::PipelineMonteCarloOptions& o) {
  return (o.units > 1 ? fmt::format(", a fixture of {} units, each scored", o.units) : "") +
         (o.random_walk > 0 ? fmt::format(", random walk {}", o.random_walk) : "") +
         (o.lever_arm_m.size() == 3
              ? fmt::format(", lever arm [{:g}, {:g}, {:g}] m", o.lever_arm_m[0], o.lever_arm_m[1],
                            o.lever_arm_m[2])
              : std::string()) +
         (o.station_warmup >= 0 ? fmt::format(", station warm-up allowance {}", o.station_warmup)
                                : std::string());
}

void PrintPipelineText(const montecarlo::PipelineMonteCarloOptions& o,
                       const montecarlo::PipelineMonteCarloSummary& s) {
  int bad = 0;
  const std::string z_table = ZScoreTable(s.parameters, s.z, false, &bad);
  fmt::print(
      "Monte Carlo through the pipeline: {} runs of {} ({} class, {}, plan {}{}{}; {:.0f} "
      "poses and {:.0f} s of session on average), seed {}; {} solved; {:.1f} s wall, {} "
      "jobs\n\n{}",
      o.runs, o.model, o.sensor_class, o.protocol, o.plan + PlanConditions(o),
      o.warmup > 0 ? fmt::format(", warm-up {} x bias instability", o.warmup) : "", DriftText(o),
      s.poses_mean, s.session_s_mean, o.seed, s.solved, s.wall_s, o.jobs, z_table + UnitLines(s));
  fmt::print(
      "\nchi^2 p-values against uniform: Kolmogorov-Smirnov D = {:.3f}, p = {:.3g} ({})\n"
      "gate passed in {} of {} runs; first passed after {:.2f} poses (at most {}) and {:.1f} s "
      "of session on average ({} runs){}\n"
      "Criteria: std z in [0.9, 1.1] and |mean z| <= 0.15 for every parameter, KS p > 0.01; "
      "{} of {} parameters fail{}.\n",
      s.ks.d, s.ks.p, s.ks.p > 0.01 ? "ok" : "NOT UNIFORM", s.gate_pass, s.solved, s.poses_to_gate,
      s.poses_to_gate_max, s.seconds_to_gate, s.activated,
      s.predicted_poses > 0
          ? fmt::format("; the planner predicted it after {} poses", s.predicted_poses)
          : "",
      bad, s.parameters.size(),
      s.solved < static_cast<int>(s.runs.size())
          ? fmt::format("; {} runs without an estimate (first: {})",
                        static_cast<int>(s.runs.size()) - s.solved, s.first_error)
          : "");
}

}  // namespace

int RunPipelineMonteCarloCommand(const PipelineMonteCarloArgs& args) {
  montecarlo::PipelineMonteCarloOptions options = args.engine;
  options.progress = [&](int finished) {
    if (!args.json && finished % 20 == 0) {
      fmt::print(stderr, "turncal montecarlo: {} of {} runs\n", finished, options.runs);
    }
  };
  const montecarlo::PipelineMonteCarloSummary s = montecarlo::RunPipelineMonteCarlo(options);
  if (!s.error.empty()) {
    fmt::print(stderr, "turncal montecarlo: {}\n", s.error);
    return s.bad_options ? 2 : 1;
  }
  if (!args.runs_out.empty() && !WriteRuns(args.runs_out, s)) {
    fmt::print(stderr, "turncal montecarlo: cannot write '{}'\n", args.runs_out);
    return 2;
  }
  if (s.solved < 2) {
    fmt::print(stderr, "turncal montecarlo: {} of {} runs gave an estimate ({})\n", s.solved,
               options.runs, s.first_error);
    return 1;
  }
  if (args.json) {
    PrintPipelineJson(options, s);
  } else {
    PrintPipelineText(options, s);
  }
  return s.Passed() ? 0 : 1;
}

void AddPipelineMonteCarloOptions(CLI::App* mc, PipelineMonteCarloArgs* args) {
  montecarlo::PipelineMonteCarloOptions* pipe = &args->engine;
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
      "--runs-out", args->runs_out,
      "with --pipeline: one JSON line per run (seed, z per parameter, chi^2 p-value, "
      "the gate and its reasons, the poses the sequencer rejected and why) to this file");
  mc->add_option("--chamber", pipe->chamber,
                 "with --pipeline: a climate chamber's profile (as turncal sim --chamber); the "
                 "station calibrates MODEL@T and each parameter is judged at --held-out "
                 "temperatures (default: between the set-points), each coefficient too with "
                 "--thermal-orders truth")
      ->type_name("PROFILE");
  mc->add_option("--device-rate", pipe->rate_hz,
                 "with --pipeline: the simulated device's output rate, Hz (default: the "
                 "protocol's); with --noise session: the simulator's (default 100)")
      ->check(CLI::NonNegativeNumber);
  mc->add_option("--mag-rate", pipe->mag_rate_hz,
                 "with --pipeline: the magnetometer's own rate below the device's, Hz (each "
                 "value held until the next, as an Xsens or MIP with a slower magnetometer "
                 "sends it; default: every sample a new value)")
      ->check(CLI::NonNegativeNumber);
  CLI::Option* keep = mc->add_option(
      "--keep", pipe->keep_dir,
      "with --pipeline: keep the captures of runs with a parameter beyond 4 sigma in "
      "this folder (run-SEED.tcap), for turncald --replay");
  mc->add_option("--units", pipe->units,
                 "with --pipeline: a fixture of this many units on one table, in four mounts in "
                 "turn (+x+y+z, -y+x+z, +x-y-z, +z+x+y), each scored against its own truth; "
                 "every unit's parameters must be honest (docs/BATCH.md)")
      ->check(CLI::Range(1, 16))
      ->capture_default_str();
  mc->add_option("--keep-p-below", pipe->keep_p_below,
                 "with --keep: also keep the runs whose chi^2 p-value is below this")
      ->check(CLI::Range(0.0, 1.0))
      ->needs(keep);
}

}  // namespace turncal::tools
