#pragma once
// What every client command of turncald shares (client_commands.h, watch_command.h,
// pose_command.h): --socket and --json, the error exit, one request and its reply, the progress
// bar and a pose's text.

#include <CLI/CLI.hpp>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>

#include "tools/client_connection.h"

namespace turncal::tools {

struct Common {
  std::string socket = DefaultSocketPath();
  bool json = false;
};

void AddCommon(CLI::App* cmd, Common* c);

// The message on standard error as "turncal COMMAND: message"; returns 2.
int Fail(const std::string& command, const std::string& message);

// A bar of `width` characters filled to `fraction`: [####....].
std::string ProgressBar(double fraction, int width);

// "phi P gamma G psi S" of a pose's JSON, "?" when it is none.
std::string PoseJsonText(const nlohmann::json& p);

// The batch slot by slot (status' and BATCH's "batch", docs/BATCH.md): a heading with the counts,
// then a line per unit -- slot, device, serial, state, poses, its time to its last gate and why
// it waits or is held. "" for a batch of one unit without a fixture (nothing to add).
std::string BatchText(const nlohmann::json& batch);

// One request, its reply printed (as JSON with --json, else by `human`); 0, or 2 when the daemon
// cannot be reached or answers ERROR.
int Simple(const std::string& command, const Common& c, const nlohmann::json& request,
           const std::function<void(const nlohmann::json&)>& human);

}  // namespace turncal::tools
