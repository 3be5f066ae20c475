#pragma once
// `turncal capture --device NAME=PROTOCOL:PORT[@BAUD] -o FILE.tcap`: record a live port until
// SIGINT/SIGTERM; `turncal devices --local`: the serial ports of this machine.

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddCaptureCommands(CLI::App* app);

}  // namespace turncal::tools
