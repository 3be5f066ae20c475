#pragma once
// `turncal free-montecarlo`: is a free model's sigma honest through the whole free-mode path?
// Every run simulates a tumble as bytes (random orientations of a three-axis table, exactly what
// `turncal sim` writes), runs it through the station exactly as `turncald --replay FILE --once
// --pose-source free` does (the capture's pose events ignored, the static intervals found by the
// sequencer in free mode, the model and its upstream fitted after every interval, gated), and
// compares every parameter of the final estimate with the free model's truth for the simulated
// sensor (sim/free_truth.h). Prints mean and std of z = (estimate - truth) / sigma per parameter,
// the count beyond 3 sigma, the chi^2 p-values against uniform and the gate (docs/ACCURACY.md).

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
  // The station's model of the bias wander ([station] drift_model): "gauss-markov" (the class's
  // drift, generalised least squares) or "independent" (the class's bias instability as an offset
  // per interval).
  std::string drift = "gauss-markov";
  // A warm-up after power-on: the simulator draws an offset per axis of this many bias
  // instabilities (accelerometer and magnetometer) settling with warmup_tau_s, and the station
  // allows for the same ([station] warmup, warmup_tau_s). 0: none.
  double warmup = 0.0;
  double warmup_tau_s = 60.0;
  bool verbose = false;
  bool json = false;
};

// 0 when every parameter's std z is in [0.9, 1.1] with |mean z| <= 0.15; 1 otherwise; 2 on bad
// arguments.
int RunFreeMonteCarlo(const FreeMonteCarloArgs& args);
void AddFreeMonteCarloCommand(CLI::App* app);

}  // namespace turncal::tools
