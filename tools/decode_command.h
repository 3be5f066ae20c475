#pragma once
// `turncal decode FILE --protocol P [--json]`: frames and samples of a raw byte stream, one JSON
// object a line (DESIGN.md shapes) or a readable table, then a summary of the counters.

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddDecodeCommand(CLI::App* app);

}  // namespace turncal::tools
