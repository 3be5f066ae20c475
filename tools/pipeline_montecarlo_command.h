#pragma once
// `turncal montecarlo --pipeline`: the options of the pipeline Monte Carlo
// (montecarlo/pipeline_montecarlo.h) on the montecarlo command, the run and its report.

#include <CLI/CLI.hpp>
#include <string>

#include "montecarlo/pipeline_montecarlo.h"

namespace turncal::tools {

struct PipelineMonteCarloArgs {
  montecarlo::PipelineMonteCarloOptions engine;
  bool json = false;
  std::string runs_out;  // when set: one JSON line per run (seed, z, p-value, gate) to this file
};

// The options that only --pipeline uses, on the montecarlo command `mc`.
void AddPipelineMonteCarloOptions(CLI::App* mc, PipelineMonteCarloArgs* args);

// Runs the engine and prints its summary. Exit status: 0 when every criterion holds, 1 when one
// does not (or the planner cannot plan, or fewer than two runs gave an estimate), 2 on an option
// that cannot work (an unknown protocol, model or class, a --runs-out file that cannot be
// written).
int RunPipelineMonteCarloCommand(const PipelineMonteCarloArgs& args);

}  // namespace turncal::tools
