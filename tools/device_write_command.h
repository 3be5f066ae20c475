#pragma once
// `turncal device-write DEVICE --model M [--save] [--dry-run] [--yes]` and
// `turncal device-write DEVICE --restore [--save]`: a device's active calibration into its stored
// calibration, through turncald (issue 23, docs/protocol.md "Writing a calibration into the
// device"). The plan is shown first (what the device holds, what will be written, with 1 sigma,
// the expected change of the output and what stays in turncald's stream); without --yes the
// command asks on a terminal and refuses without one.

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddDeviceWriteCommand(CLI::App* app);

}  // namespace turncal::tools
