#pragma once
// Planning a calibration over temperature in chamber and table time (issue 36; `turncal
// plan-thermal`, docs/OBSERVABILITY.md "Over temperature"). Each candidate procedure is simulated
// in memory -- the chamber's air, the sensor's die lagging it (first order, tau), the table
// cycling the 26 cube poses, each pose a record at the die's mean temperature over its dwell
// (sim/synthetic.h: white noise and a pose-to-pose bias offset) drawn from a device whose every
// parameter is a quadratic in temperature (sim/thermal_truth.h) -- and the real calibration over
// temperature and its gate (core/analysis/thermal_gate.h) run as the poses come, until the gate
// passes over the whole range. What each procedure costs is the chamber-and-table time from a
// device soaked at the range's low end to that passing gate.
//
// The procedures:
//   - classic: `plateaus` set-points evenly over the range; the chamber ramps to each at its
//     fastest rate, waits until the die has settled (the station's soak test, core/sequencing/
//     soak.h: the die's slope over `soak_window_s` below `soak_rate_c_per_min`), then the 26 cube
//     poses (or, when that does not pass in every run, twice or three times: what a lab repeats
//     until it passes); no pose while the chamber moves;
//   - ramp at R degC/min: the chamber ramps from the low end to the high end at R and, once the die
//     is within the coverage of that end and a cube there has not passed the gate, back (up to
//     three legs, and never longer than the classic procedure took); the
//     table cycles the cube poses from the start, each pose counting at the temperature it was
//     taken at.
// The plan is the quickest ramp whose gate passed in every run (its slowest run's time); the ramps
// are simulated fastest first, and one whose ramp alone takes longer than the classic procedure or
// a quicker passing ramp is not simulated.

#include <string>
#include <vector>

namespace turncal::montecarlo {

struct ThermalPlanOptions {
  std::string model = "accel13";  // a model calibrated from static poses (accel13, mag13)
  std::string sensor_class = "industrial";
  double t_lo_c = 0.0, t_hi_c = 40.0;
  double chamber_max_rate_c_per_min = 2.0;  // the chamber's fastest ramp
  double die_tau_s = 300.0;                 // the die's lag behind the air
  double dwell_s = 5.0;
  int plateaus = 5;  // the classic procedure's set-points, the ends included
  std::vector<double> ramp_rates_c_per_min = {0.25, 0.5, 1.0, 2.0};
  // Each ramp also with the cube this many times at each end: at the low end (where the device
  // starts, soaked) before the chamber moves, and at the far end before it turns back (0: one
  // cube at the far end only). The poses where the polynomials' sigma is largest.
  std::vector<int> end_cubes = {0};
  double soak_rate_c_per_min = 0.05;  // the classic procedure's soak test
  double soak_window_s = 60.0;
  // A ramp may drive the chamber's air this far past the range's ends (the die, lagging, then
  // reaches the end sooner); 0: never past the range (the device's rating may forbid more).
  double overshoot_c = 0.0;
  // The range counts as covered once the poses reach within this of both ends.
  double coverage_c = 1.0;
  int refit_every = 4;  // poses between two fits and gate checks
  int runs = 5;
  unsigned long long seed = 1;
  int jobs = 1;

  bool IsValid(std::string* error) const;
};

// One procedure over the runs.
struct ThermalProcedureOutcome {
  std::string name;             // "classic: 5 soaks" or "ramp 1 degC/min"
  std::string chamber;          // the chamber's profile (turncal sim --chamber syntax)
  double rate_c_per_min = 0.0;  // 0: the classic procedure
  int legs = 1;                 // a ramp's legs between the ends in the slowest run
  int cubes = 1;                // the classic procedure: the cube this many times at each plateau
  int end_cubes = 0;            // a ramp: the cube this many times at each end (0: once at the far)
  bool skipped = false;  // a ramp not simulated: its ramp alone outlasts a quicker passing plan
  std::vector<double> seconds;  // per run, to the passing gate; negative: never passed
  std::vector<int> poses;       // per run, poses to the passing gate
  std::vector<double> chi2_p;   // per run, the p-value of its last fit's chi^2 (NaN: none)
  std::string last_reason;      // a failing run's last gate reason
  int failures() const;
  double median_seconds() const;  // over the runs that passed; NaN when none did
  double max_seconds() const;
  double min_seconds() const;
};

struct ThermalPlan {
  double pose_s = 0.0;  // table seconds per pose (move, settling and dwell)
  ThermalProcedureOutcome classic;
  std::vector<ThermalProcedureOutcome> ramps;
  int chosen = -1;  // index into ramps; -1: no ramp passed in every run
  std::string error;
};

ThermalPlan PlanOverTemperature(const ThermalPlanOptions& options);

}  // namespace turncal::montecarlo
