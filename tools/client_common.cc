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

std::string BatchText(const nlohmann::json& b) {
  if (!b.is_object() || !b["units"].is_array()) return "";
  const bool fixture = b["fixture"].is_string();
  if (b["units"].size() < 2 && !fixture) return "";
  auto text = [](const nlohmann::json& v) {
    return v.is_string() ? v.get<std::string>() : v.is_null() ? std::string("-") : v.dump();
  };
  std::string out = fmt::format(
      "batch {}{} (started {}): {} passed, {} waiting, {} held", text(b["id"]),
      fixture ? " on fixture " + b["fixture"].get<std::string>() : std::string(),
      text(b["started"]), b.value("passed", 0), b.value("waiting", 0), b.value("held", 0));
  if (b["seconds_to_last_gate"].is_number()) {
    out += fmt::format("; the last gate after {:.0f} s", b["seconds_to_last_gate"].get<double>());
  }
  out += fmt::format("\n  {:6} {:10} {:12} {:8} {:>5} {:>7}  {}\n", "slot", "device", "serial",
                     "state", "poses", "time", "why");
  for (const auto& u : b["units"]) {
    const std::string link = u.value("link", "");
    const std::string why = u.value("why", "");
    out += fmt::format(
        "  {:6} {:10} {:12} {:8} {:>5} {:>7}  {}\n", text(u["slot"]), text(u["device"]),
        text(u["serial"]), text(u["state"]), u.value("poses", 0),
        u["seconds"].is_number() ? fmt::format("{:.0f} s", u["seconds"].get<double>()) : "-",
        why + (!link.empty() && link != "streaming" && why.find(link) == std::string::npos
                   ? " (device " + link + ")"
                   : ""));
  }
  return out;
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
