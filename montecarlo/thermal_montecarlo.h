#pragma once
// Is the calibration over temperature honest, and what does it gain over offset-only
// polynomials (`turncal montecarlo --thermal`; issue 36)? Many sensors drawn from a class with
// their parameters as polynomials in temperature (sim/thermal_truth.h), each calibrated in memory
// from the 26 cube poses at each soak temperature (white pose means with the class's pose-to-pose
// offset, sim/synthetic.h): the z-scores of every coefficient (with the truth's orders), of every
// parameter at held-out temperatures between the soaks, the chi^2 p-values' uniformity, and the
// error the calibration leaves in the corrected output over the range against PX4's and
// ArduPilot's method -- the biases alone as cubics in temperature, the rest constant -- fitted to
// the same poses.

#include <cstdint>
#include <string>
#include <vector>

#include "montecarlo/ks_uniform.h"
#include "montecarlo/z_scores.h"

namespace turncal::montecarlo {

struct ThermalMonteCarloOptions {
  std::string model = "accel13";
  std::string sensor_class = "industrial";
  std::vector<double> soaks_c = {-20.0, 5.0, 25.0, 45.0, 70.0};
  // Where each parameter is checked besides the coefficients (empty: the midpoints between
  // consecutive soaks).
  std::vector<double> held_out_c;
  // "truth": each parameter's order as the truth's (the coefficients' z-scores are then
  // comparable across runs); "chosen": from the data (core/estimation/thermal_calibrator.h);
  // "full": every parameter at ThermalOptions::max_order.
  std::string orders = "truth";
  // With orders "chosen": ThermalOptions::drop_below_sigmas.
  double drop_below_sigmas = 0.25;
  double dwell_s = 5.0;
  std::uint64_t seed = 1;  // run r's is seed * 1000003 + r
  int runs = 200;
  int jobs = 1;
};

struct ThermalRun {
  bool ok = false;
  std::string error;
  Eigen::VectorXd z;       // per coefficient (orders "truth"), else empty
  Eigen::VectorXd z_held;  // per parameter and held-out temperature
  double p_value = 1.0;
  // Mean square of |corrected - true| over the cube poses at 21 temperatures across the soaks:
  // turncal's thermal model, and the offset-only cubics.
  double ms_error_full = 0.0, ms_error_offset_only = 0.0;
  double solve_ms = 0.0;
};

struct ThermalMonteCarloSummary {
  std::string error;                      // the runs did not start
  std::vector<std::string> coefficients;  // orders "truth"
  std::vector<std::string> held_out;      // "bx at 35 degC"
  std::string unit;                       // of the output errors
  double class_noise = 0.0;               // the class's white noise over one 5 s pose, same unit
  std::vector<ThermalRun> runs;
  int solved = 0;
  std::string first_error;
  ZScoreSummary z, z_held;
  KsTest ks;
  double rms_error_full = 0.0, rms_error_offset_only = 0.0;
  double mean_solve_ms = 0.0;

  // Every coefficient and held-out value honest (ZScoreSummary::Honest), chi^2 p-values uniform
  // (KS p > 0.01), every run solved.
  bool Passed() const;
};

ThermalMonteCarloSummary RunThermalMonteCarlo(const ThermalMonteCarloOptions& options);

}  // namespace turncal::montecarlo
