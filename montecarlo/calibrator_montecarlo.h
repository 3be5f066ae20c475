#pragma once
// Is the calibrator's reported sigma honest (`turncal montecarlo` without --pipeline)? Many
// sessions simulated in memory along one pose design, each with new truth and noise, calibrated
// by the calibrator alone: per parameter the RMSE of the estimates against the mean reported
// sigma (the Cramer-Rao bound when the noise model is right) and the z-scores' mean and spread
// (docs/ACCURACY.md).

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "core/frames/table_pose.h"
#include "montecarlo/ks_uniform.h"
#include "montecarlo/z_scores.h"

namespace turncal::montecarlo {

// `count` poses of a design: "cube" (the 26 cube directions, each repeat turned 45 deg about the
// outer axis), "random" (drawn from `rng`) or "about-z" (a turn about the vertical only: a
// degenerate design).
std::vector<TablePose> DesignPoses(const std::string& design, int count, std::mt19937_64* rng);

struct CalibratorMonteCarloOptions {
  std::string model = "accel13";
  std::string sensor_class = "industrial";
  int poses = 60;
  std::string design = "random";
  bool shuffle = false;  // the design's poses in a random order (the same for every run)
  double dwell_s = 5.0;
  std::uint64_t seed = 1;  // the design's; run r's is seed * 1000003 + r
  int runs = 200;
  // "white": pose means with white noise and independent pose offsets (sim/synthetic.h);
  // "session": the session simulator's full noise model at 100 Hz (sim/session_sim.h), the
  // calibrator with the class's drift as a process in time ("gauss-markov") or an independent
  // offset per pose ("independent", the model before issue 19).
  std::string noise = "white";
  std::string drift_model = "gauss-markov";
  double rate_hz = 100.0;  // "session": the simulated output rate
};

struct CalibratorMonteCarloSummary {
  std::string error;  // an unknown model or class: the runs did not start
  std::string sensor_class;
  int poses = 0;  // in the design
  std::vector<std::string> parameters;
  int solved = 0, failed = 0;
  double mean_solve_ms = 0.0;  // over the solved runs (0 without)
  // Per parameter over the solved runs: the RMSE of the estimates, the RMS of the reported
  // sigma, their z-scores.
  Eigen::VectorXd rmse, sigma;
  ZScoreSummary z;
  // Each solved run's chi^2 p-value and their Kolmogorov-Smirnov test against uniform (reported;
  // not among Passed()'s criteria: "white" and "independent" runs are comparisons).
  std::vector<double> p_values;
  KsTest ks;

  // The verdict on a parameter: RMSE <= 1.1 sigma and std z in [0.9, 1.1].
  bool Honest(int parameter) const;
  // Every parameter honest and every run solved.
  bool Passed() const;
};

CalibratorMonteCarloSummary RunCalibratorMonteCarlo(const CalibratorMonteCarloOptions& options);

}  // namespace turncal::montecarlo
