#pragma once
// `turncal status|devices|watch|pose|result|next-pose|report|reset|publish`: the client of a
// running turncald (docs/protocol.md). Every command takes --socket PATH (default
// $TURNCAL_SOCKET or /run/turncal/turncal.sock) and --json (the daemon's replies as they are,
// one JSON object a line). Exit codes: 0 done (pose: captured on every device), 1 pose rejected
// on some device, 2 a usage or connection error, or an ERROR reply. watch, pose and rate are in
// watch_command.cc and pose_command.cc; AddClientCommands adds them in their place.

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddClientCommands(CLI::App* app);

}  // namespace turncal::tools
