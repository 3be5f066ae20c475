#pragma once
// Offline, in-memory calibration experiments on synthetic data with known truth:
//   turncal fit-sim     one simulated session: truth, estimate, 1 sigma, normalised error
//   turncal montecarlo  many sessions: is the reported uncertainty honest? (the engines in
//                       montecarlo/; --pipeline's options in pipeline_montecarlo_command.h)

#include <CLI/CLI.hpp>

namespace turncal::tools {
void AddSimFitCommands(CLI::App* app);
}
