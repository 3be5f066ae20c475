#pragma once
// Is a free model's sigma honest through the whole free-mode path (`turncal free-montecarlo`)?
// Every run simulates a tumble as bytes (random orientations of a three-axis table, exactly what
// `turncal sim` writes), runs it through the station exactly as `turncald --replay FILE --once
// --pose-source free` does (the capture's pose events ignored, the static intervals found by the
// sequencer in free mode, the model and its upstream fitted after every interval, gated), and
// compares every parameter of the final estimate with the free model's truth for the simulated
// sensor (sim/free_truth.h). The summary: mean and std of z = (estimate - truth) / sigma per
// parameter, the count beyond 3 sigma, the chi^2 p-values against uniform and the gate
// (docs/ACCURACY.md "Without a turntable").

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "montecarlo/ks_uniform.h"
#include "montecarlo/z_scores.h"

namespace turncal::montecarlo {

struct FreeRun;

struct FreeMonteCarloOptions {
  std::string model = "accel9";
  std::string sensor_class = "industrial";
  std::string protocol = "mip";
  int runs = 200;
  std::uint64_t seed = 1;  // run r's seed is seed * 1000003 + r
  int jobs = 2;
  int orientations = 30;
  double dwell_s = 4.0;
  double cap_deg = 180.0;  // up within this many degrees of the table's +z
  bool field_known = true;
  // The station's model of the bias wander ([station] drift_model): "gauss-markov" (the class's
  // drift, generalised least squares) or "independent" (the class's bias instability as an offset
  // per interval).
  std::string drift = "gauss-markov";
  // A warm-up after power-on: the simulator draws an offset per axis of this many bias
  // instabilities (accelerometer and magnetometer) settling with warmup_tau_s, and the station
  // allows for the same ([station] warmup, warmup_tau_s). 0: none.
  double warmup = 0.0;
  double warmup_tau_s = 60.0;
  // A hand's continuous rotation (issue 37; sim/hand_motion.h) instead of the table's static
  // orientations: its length in s (0: the table's tumble), RMS rate, path and pauses (every
  // pause_every_s of motion a pause of pause_s; 0: none), the device's rate and the
  // magnetometer's own (0: the protocol's default; a new value in every sample). These runs go
  // through what `turncal free` fits (the still intervals and the magnetometer's samples in
  // motion, core/estimation/free_motion.h) with the station's context, not yet through the
  // station itself.
  double hand_s = 0.0;
  double hand_rate_dps = 90.0;
  std::string hand_path = "tumble";
  double hand_pause_every_s = 0.0;
  double hand_pause_s = 3.0;
  double device_rate_hz = 0.0;
  double mag_rate_hz = 0.0;
  // The magnetometer's first-order low-pass, Hz (SessionSimOptions::mag_bandwidth_hz; 0: none),
  // and whether the station is told it ([free] mag_bandwidth_hz) or not (what ignoring it costs).
  double mag_bandwidth_hz = 0.0;
  double mag_lag_s = 0.0;  // SessionSimOptions::mag_lag_s
  bool bandwidth_known = true;
  bool mag_noise_filtered = false;  // SessionSimOptions::mag_noise_filtered
  // A magnet passing by at magnet_at_s (s into the session; < 0: none) for magnet_s, its
  // field's peak magnet_peak (Gauss; SessionSimOptions::magnet_*): the station must leave the
  // disturbed values out and stay honest.
  double magnet_at_s = -1.0, magnet_s = 1.0, magnet_peak = 0.1;
  // Called after each run that reached an estimate of the model, with the run's number, its
  // outcome, the number of such runs so far and the model's parameters (the outcome's order);
  // one call at a time (the runs run on `jobs` threads).
  std::function<void(int run, const FreeRun& outcome, int scored,
                     const std::vector<std::string>& parameters)>
      on_run;
};

struct FreeRun {
  bool ok = false;  // an estimate with a finite z for every parameter
  std::string error;
  Eigen::VectorXd theta, truth, sigma, z;  // per parameter (sigma infinite where not reported)
  double p_value = 1.0;
  bool gated = false;                // the model's gate judged the run (pass or refuse)
  bool gate = false;                 // and passed it
  std::vector<std::string> reasons;  // why it refused, numbers as '#' (GateReasonKind)
  int intervals = 0;
  // A hand's rotation with magellipsoid: the hard iron's error |b - b_true| (device unit) of
  // turncal's estimate and of the plain least-squares fits the vendors' tools make (a sphere by
  // Kasa's linear fit, an algebraic ellipsoid: core/models/free_common.h) through every new
  // magnetometer value of the session, unweighted; NaN where a fit failed or was not made.
  double hard_iron_error = NAN, sphere_error = NAN, ellipsoid_error = NAN;
  // The largest second-order bias the fit removed, in sigmas (core/estimation/free_bias.h); 0
  // when none.
  double norm_bias_sigmas = 0.0;
};

// The hard iron's error over the runs that have it, for one method: RMS, median and the largest.
struct HardIronErrors {
  int runs = 0;
  double rms = NAN, median = NAN, max = NAN;
};

struct FreeMonteCarloSummary {
  std::string error;  // set when the runs could not start (an option that cannot work: exit 2)
  std::vector<std::string> parameters;  // the model's, in order
  std::vector<FreeRun> runs;
  // The gate over every run it judged (also those whose sigma is not finite: a low-coverage
  // tumble's undetermined directions), and its five commonest reasons, alike ones counted
  // together, commonest first.
  int gated = 0, gate_passed = 0;
  std::vector<std::pair<int, std::string>> top_reasons;
  // Over the runs with finite z-scores (`solved`), when at least two:
  int solved = 0;
  std::string first_error;  // the first run without one's
  ZScoreSummary z;
  KsTest ks;
  // The chi^2 p-values per tenth of [0, 1]: uniform when the noise model is right (too many near
  // 0: chi^2 too large; near 1: too small).
  std::vector<int> p_value_deciles;
  double intervals_mean = 0.0;
  // With a hand's rotation and magellipsoid: the hard iron's error, turncal's against the plain
  // fits on the same values (FreeRun::hard_iron_error ...).
  HardIronErrors hard_iron, plain_sphere, plain_ellipsoid;
  // The largest second-order bias removed per run, in sigmas: median and largest over the runs.
  double norm_bias_median = 0.0, norm_bias_max = 0.0;

  bool Passed() const;  // every parameter honest (ZScoreSummary::Honest)
};

FreeMonteCarloSummary RunFreeMonteCarlo(const FreeMonteCarloOptions& options);

// A gate reason with its numbers replaced by '#': refusals for the same cause count together.
std::string GateReasonKind(const std::string& reason);

}  // namespace turncal::montecarlo
