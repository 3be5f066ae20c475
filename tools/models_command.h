#pragma once
// `turncal models [--json]`: the measurement models and their parameters.

#include <CLI/CLI.hpp>

namespace turncal::tools {
void AddModelsCommand(CLI::App* app);
}
