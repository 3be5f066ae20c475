#include "tools/client_common.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace turncal::tools {

void AddCommon(CLI::App* cmd, Common* c) {
  cmd->add_option("--socket", c->socket, "turncald's socket ($TURNCAL_SOCKET)")
      ->capture_default_str();
  cmd->add_flag("--json", c->json, "print the daemon's JSON replies, one object a line");
}

int Fail(const std::string& command, const std::string& message) {
  fmt::print(stderr, "turncal {}: {}\n", command, message);
  return 2;
}

std::string ProgressBar(double fraction, int width) {
  fraction = std::clamp(fraction, 0.0, 1.0);
  const int full = static_cast<int>(std::lround(fraction * width));
  return "[" + std::string(static_cast<std::size_t>(full), '#') +
         std::string(static_cast<std::size_t>(width - full), '.') + "]";
}

std::string PoseJsonText(const nlohmann::json& p) {
  if (!p.is_object()) return "?";
  return fmt::format("phi {:.1f} gamma {:.1f} psi {:.1f}", p.value("phi_deg", 0.0),
                     p.value("gamma_deg", 0.0), p.value("psi_deg", 0.0));
}

int Simple(const std::string& command, const Common& c, const nlohmann::json& request,
           const std::function<void(const nlohmann::json&)>& human) {
  ClientConnection conn;
  std::string error;
  if (!conn.Connect(c.socket, &error)) return Fail(command, error);
  auto reply = conn.Request(request, &error);
  if (!reply) return Fail(command, error);
  if (reply->value("class", "") == "ERROR") {
    if (c.json) fmt::print("{}\n", reply->dump());
    return Fail(command, reply->value("message", "error"));
  }
  if (c.json) {
    fmt::print("{}\n", reply->dump());
  } else {
    human(*reply);
  }
  return 0;
}

}  // namespace turncal::tools
