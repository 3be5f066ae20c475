#pragma once
// `turncal pose` and `turncal rate`: announce the table's pose or rate segment to a running
// turncald and wait until every device captured or rejected it (docs/protocol.md).

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddPoseCommands(CLI::App* app);

}  // namespace turncal::tools
