#pragma once
// Is the reported sigma honest through the whole pipeline (`turncal montecarlo --pipeline`)?
// Every run simulates a session as bytes (sim/capture.h, exactly what `turncal sim` writes),
// writes the capture, replays it through the station exactly as `turncald --replay CAPTURE
// --once` does (daemon/station/replay_once.h) with only the model under test configured, and
// compares every parameter with the truth the simulator defines for it (the biases over the
// calibration's bias window). The summary: mean and std of z = (estimate - truth) / sigma per
// parameter, the chi^2 p-values against uniform (Kolmogorov-Smirnov) and the gate's verdicts
// (docs/ACCURACY.md).

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "montecarlo/ks_uniform.h"
#include "montecarlo/z_scores.h"

namespace turncal::montecarlo {

struct PipelineMonteCarloOptions {
  std::string model = "accel13";
  std::string sensor_class = "industrial";
  std::string protocol = "mip";
  // default: DefaultSessionPoses (26 cube directions in loop order + 10); shuffled: the same
  // poses in a new random order every run; planner: the D-optimal planner's sequence to the gate
  // from nominal values (as `turncal plan` prints it; a gyroscope model alone, with the rate
  // segments at sim/session_sim.h's default rates unless the sources are "moves", and the moves
  // credited for "moves" and "all").
  std::string plan = "default";
  // A gyroscope model's sources (issue 21): "mixed" (the plan's static poses with the default
  // rate segments after the first of them, sim/session_sim.h DefaultRateSegments), "rates"
  // (the rate segments alone), "moves" (the static poses and the moves between them) or "all"
  // (the static poses with their moves, then the rate segments).
  std::string gyro_sources = "mixed";
  int runs = 200;
  std::uint64_t seed = 1;  // run r's seed is seed * 1000003 + r
  int jobs = 2;
  double dwell_s = 5.0;
  // Drift the station is not told about (0: none): warm-up and random walk of both triads, in
  // units of the class's bias instability (warm-up: 1 sigma at power-on; random walk: per
  // sqrt(100 s)).
  double warmup = 0.0;
  double warmup_tau_s = 60.0;
  double random_walk = 0.0;
  // The IMU's lever arm from the table's centre in q, m (empty: none; sim/session_sim.h).
  std::vector<double> lever_arm_m;
  // The simulated bias instability in units of the class's (the station keeps the class's as
  // its prior), and whether the station identifies the drift's strength ([station]
  // identify_drift).
  double drift_scale = 1.0;
  bool identify_drift = true;
  // The station's warm-up allowance ([station] warmup, in bias instabilities; negative: none).
  double station_warmup = -1.0;
  bool independent = false;  // the station's model before issue 19 ([station] drift_model)
  // Which estimate is judged: "end" (after every pose of the plan) or "first-gate" (the
  // calibration the gate first activated, from the state directory's history).
  std::string at = "end";
  int gate_min_dof = -1;  // the gate's redundant equations (GateOptions::min_dof); < 0: default
  // The simulated table: moves at this rate (deg/s) and acceleration; 0: every move takes 3 s.
  // The planner plans for the same table.
  double table_rate_dps = 0.0;
  double table_accel_dps2 = 20.0;
  // The planner's objective ("time" or "poses") and whether it plans with the class's drift
  // model ("gauss-markov") or independent poses ("independent": the planner before issue 19).
  std::string planner_objective = "time";
  std::string planner_drift = "gauss-markov";
  // A climate chamber (issue 36; docs/THERMAL.md): its profile (sim/chamber.h's text form; empty:
  // none). The poses are then cycled until it has run, the station calibrates MODEL@T, and each
  // parameter is judged at the held-out temperatures (empty: DefaultHeldOutTemperatures) and,
  // with thermal_orders "truth" (the station fits the truth's orders about its t0), each
  // coefficient too.
  std::string chamber;
  std::vector<double> held_out_c;
  std::string thermal_orders = "chosen";
  double rate_hz = 0.0;  // the simulated device's output rate (0: the protocol's default)
  // The magnetometer's own rate below the output rate: each value held until the next (0: every
  // sample a new value).
  double mag_rate_hz = 0.0;
  // A fixture of this many units on one table (issue 38; docs/BATCH.md): each run simulates
  // that many units of the same plan in sim::kFixtureMounts' four mounts in turn, each with its
  // own seed and truth, and replays them as one capture through one station with their mounts
  // configured; each unit's estimate is scored as a run of its own (PipelineRun::unit). Not in a
  // chamber.
  int units = 1;
  std::string keep_dir;  // when set: the captures of runs with a parameter beyond 4 sigma go here
  double keep_p_below = 0.0;  // with keep_dir: also the runs whose chi^2 p-value is below this
  // Called after each run that gave an estimate with the number of such runs so far, one call at
  // a time (the runs run on `jobs` threads).
  std::function<void(int solved)> progress;
};

// One run, as `--runs-out` writes it.
struct PipelineRun {
  bool ok = false;  // an estimate with finite z for every parameter
  std::string error;
  std::uint64_t seed = 0;
  int unit = 0;  // with units > 1: the unit of its session (0: the first)
  Eigen::VectorXd z;
  double p_value = 1.0;
  bool gate_pass = false;
  nlohmann::json gate_reasons = nlohmann::json::array();  // the gate's reasons at the end
  nlohmann::json rejected = nlohmann::json::array();      // the sequencer's rejection reasons
  int poses = 0;
  double session_s = 0.0;
  int gate_poses = -1;  // poses at the first activation (-1: never)
  double gate_s = NAN;  // session seconds at the first activation
};

struct PipelineMonteCarloSummary {
  // Set when the runs could not start: `bad_options` for an unknown protocol, model or class
  // (exit 2), else the planner's refusal (exit 1).
  std::string error;
  bool bad_options = false;
  // What each run's z holds: the model's parameters in order, or in a chamber
  // montecarlo/pipeline_thermal.h's ThermalScoredNames.
  std::vector<std::string> parameters;
  bool gyro = false;         // a gyroscope model
  int predicted_poses = -1;  // --plan planner: the planner's prediction of the gate
  std::vector<PipelineRun> runs;
  double wall_s = 0.0;
  // Over the runs that gave an estimate (`solved`), when at least two did:
  int solved = 0;
  std::string first_error;  // the first run without an estimate's
  ZScoreSummary z;
  KsTest ks;  // the chi^2 p-values against uniform
  int gate_pass = 0;
  int activated = 0;  // runs whose gate passed at some pose
  double poses_mean = 0.0, session_s_mean = 0.0;
  double poses_to_gate = NAN, seconds_to_gate = NAN;  // mean over the activated runs
  int poses_to_gate_max = 0;
  // With units > 1: each unit's z-scores over its sessions (every unit's parameters honest is
  // part of Passed), and its mount's text.
  std::vector<ZScoreSummary> unit_z;
  std::vector<std::string> unit_mounts;

  // Every parameter honest (ZScoreSummary::Honest) over all runs, every unit of a fixture's
  // parameters honest by UnitHonest, the p-values uniform (KS p > 0.01) and every run with an
  // estimate.
  bool Passed() const;
  // One unit of a fixture: its n sessions' std z within 1 +- kUnitHonestZ / sqrt(2 n) and its
  // mean z within +-kUnitHonestZ / sqrt(n) -- their sampling errors' 3.5 sigma, so that the
  // 4 x 13 statistics of an honest 4-unit fixture all pass in ~95 % of the rows (the pooled
  // [0.9, 1.1] and 0.15, at 200 sessions each statistic's ~2 sigma, fail one of 52 statistics
  // by chance in most rows). 200 sessions: std z in [0.825, 1.175], |mean z| <= 0.247.
  static constexpr double kUnitHonestZ = 3.5;
  static bool UnitHonest(const ZScoreSummary& u, int parameter);
};

PipelineMonteCarloSummary RunPipelineMonteCarlo(const PipelineMonteCarloOptions& options);

}  // namespace turncal::montecarlo
