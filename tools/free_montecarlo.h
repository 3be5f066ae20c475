#pragma once
// `turncal free-montecarlo`: is a free model's sigma honest through the whole free-mode path?
// Every run simulates a tumble as bytes (random orientations of a three-axis table, exactly what
// `turncal sim` writes, the table's announced poses ignored), decodes it, finds its static
// intervals with the sequencer in free mode, fits the model (and its upstream) as `turncal free`
// does, and compares every parameter with the free model's truth for the simulated sensor
// (sim/free_truth.h). Prints mean and std of z = (estimate - truth) / sigma per parameter, the
// count beyond 3 sigma, the chi^2 p-values against uniform and the gate (docs/ACCURACY.md).

#include <CLI/CLI.hpp>
#include <cstdint>
#include <string>

namespace turncal::tools {

struct FreeMonteCarloArgs {
  std::string model = "accel9";
  std::string sensor_class = "industrial";
  std::string protocol = "mip";
  int runs = 200;
  std::uint64_t seed = 1;
  int jobs = 2;
  int orientations = 30;
  double dwell_s = 4.0;
  double cap_deg = 180.0;
  bool field_known = true;
  // The calibration's model of the bias wander: "gauss-markov" (the class's drift, generalised
  // least squares), "independent" (offset_sigma x the class's bias instability per interval) or
  // "none".
  std::string drift = "gauss-markov";
  double offset_sigma = 1.0;  // the intervals' offset allowance, in the class's bias instability
  bool verbose = false;
  bool json = false;
};

// 0 when every parameter's std z is in [0.9, 1.1] with |mean z| <= 0.15; 1 otherwise; 2 on bad
// arguments.
int RunFreeMonteCarlo(const FreeMonteCarloArgs& args);
void AddFreeMonteCarloCommand(CLI::App* app);

}  // namespace turncal::tools
