#pragma once
// `turncal montecarlo --thermal SOAKS`: the calibration over temperature's Monte Carlo
// (montecarlo/thermal_montecarlo.h) on the montecarlo command, the run and its report.

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "montecarlo/thermal_montecarlo.h"

namespace turncal::tools {

struct ThermalMonteCarloArgs {
  montecarlo::ThermalMonteCarloOptions engine;
  std::vector<double> soaks_c;     // --thermal -20,5,25,45,70; empty: not asked
  std::vector<double> held_out_c;  // --held-out -5,15,35,57.5
  bool json = false;
};

// The options that only --thermal uses, on the montecarlo command `mc`.
void AddThermalMonteCarloOptions(CLI::App* mc, ThermalMonteCarloArgs* args);

// Runs the engine and prints its summary. Exit status: 0 when every criterion holds, 1 when one
// does not (a coefficient's or held-out value's std z outside [0.9, 1.1] or |mean z| > 0.15,
// chi^2 p-values not uniform, a run without an estimate), 2 on an option that cannot work (an
// unknown model or class, fewer than two soaks, a temperature list that is not numbers).
int RunThermalMonteCarloCommand(const ThermalMonteCarloArgs& args);

}  // namespace turncal::tools
