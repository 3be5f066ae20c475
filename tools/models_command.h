#pragma once
// `turncal models [--json]`: every measurement model, turntable and free, and its parameters.

#include <CLI/CLI.hpp>

namespace turncal::tools {
void AddModelsCommand(CLI::App* app);
}
