#pragma once
// `turncal noise-montecarlo`: simulated rests with known IEEE 952 terms through `turncal
// noise`'s estimator and fit, and the coverage of the terms' stated intervals
// (montecarlo/noise_montecarlo.h).

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddNoiseMonteCarloCommand(CLI::App* app);

}  // namespace turncal::tools
