#pragma once
// `turncal capture --device NAME=PROTOCOL:PORT[@BAUD] -o FILE.tcap`: record a live port until
// SIGINT/SIGTERM; RunLocalDevices for `turncal devices --local` (tools/client_commands.cc).

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddCaptureCommands(CLI::App* app);

// `turncal devices --local`: this machine's serial ports (libserialport); 0, or 2 on an error.
int RunLocalDevices(bool json);

}  // namespace turncal::tools
