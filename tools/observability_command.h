#pragma once
// `turncal observability` (structural and data-level observability of a model) and `turncal plan`
// (D-optimal next pose and the greedy plan to the publish gate), offline, from pose lists.

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddObservabilityCommands(CLI::App* app);

}  // namespace turncal::tools
