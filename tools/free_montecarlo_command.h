#pragma once
// `turncal free-montecarlo`: the options of the free-mode Monte Carlo
// (montecarlo/free_montecarlo.h), the run and its report.

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddFreeMonteCarloCommand(CLI::App* app);

}  // namespace turncal::tools
