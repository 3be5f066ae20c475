#pragma once
// `turncal watch`: the live view of a running turncald's events and samples (docs/protocol.md
// "watch").

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddWatchCommand(CLI::App* app);

}  // namespace turncal::tools
