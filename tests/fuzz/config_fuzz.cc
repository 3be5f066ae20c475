// libFuzzer target for turncald's configuration (daemon/service/config.h, ParseConfig: what
// LoadConfig and a SIGHUP reload read; systemd/turncald.toml.example documents it). The input is
// the file.
//
// Invariants checked on every input:
// - nothing escapes as an exception (turncald would die at start or on SIGHUP);
// - a refusal has a message that names the file ("fuzz.toml:LINE: ..." or "fuzz.toml: ...");
// - an accepted configuration is valid (StationOptions::IsValid), its device names are unique
//   and each has its settings, a configured rate is in (0, 4000] Hz, per-device options belong
//   to configured devices;
// - it is what the file says: each [[device]]'s name, protocol, port and baud, each numeric
//   control user's uid, the socket, group and state directory come back unchanged.
//
// Run: tests/fuzz/run_fuzz.sh BUILD_DIR SECONDS config
#include <toml++/toml.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "daemon/service/config.h"

namespace {

using turncal::daemon::Config;

bool SameOptional(const std::optional<std::string>& parsed, const toml::table& root,
                  const char* key) {
  const auto v = root[key].value<std::string>();
  return parsed == v;
}

void Check(const std::string& text) {
  Config c;
  std::string error;
  if (!turncal::daemon::ParseConfig(text, "fuzz.toml", &c, &error)) {
    if (error.rfind("fuzz.toml:", 0) != 0) __builtin_trap();
    return;
  }
  std::string why;
  if (!c.station.IsValid(&why)) __builtin_trap();
  if (c.device_settings.size() != c.devices.size()) __builtin_trap();
  for (std::size_t i = 0; i < c.devices.size(); ++i) {
    const auto& d = c.devices[i];
    if (d.name.empty() || d.port.empty() || !c.device_settings.count(d.name)) __builtin_trap();
    for (std::size_t j = 0; j < i; ++j) {
      if (c.devices[j].name == d.name) __builtin_trap();
    }
  }
  for (const auto& [name, own] : c.station.per_device) {
    if (!c.device_settings.count(name)) __builtin_trap();
  }

  // What the file says. It parsed once, so it parses again.
  const toml::table root = toml::parse(text, std::string_view("fuzz.toml"));
  if (!SameOptional(c.socket_path, root, "socket") ||
      !SameOptional(c.socket_group, root, "socket_group") ||
      !SameOptional(c.state_dir, root, "state_dir")) {
    __builtin_trap();
  }
  if (const toml::array* users = root["control_users"].as_array()) {
    if (users->size() != c.control_uids.size()) __builtin_trap();
    for (std::size_t i = 0; i < users->size(); ++i) {
      const auto* uid = (*users)[i].as_integer();
      if (uid && uid->get() != static_cast<std::int64_t>(c.control_uids[i])) __builtin_trap();
    }
  } else if (!c.control_uids.empty()) {
    __builtin_trap();
  }
  const toml::array* devices = root["device"].as_array();
  if ((devices ? devices->size() : 0) != c.devices.size()) __builtin_trap();
  for (std::size_t i = 0; i < c.devices.size(); ++i) {
    const toml::table& t = *(*devices)[i].as_table();
    const auto& d = c.devices[i];
    if (t["name"].value<std::string>() != d.name ||
        t["protocol"].value<std::string>() != std::string(turncal::drivers::ToString(d.protocol)) ||
        t["port"].value<std::string>() != d.port) {
      __builtin_trap();
    }
    if (const auto baud = t["baud"].value<double>(); baud && *baud != d.baud) __builtin_trap();
    const auto& settings = c.device_settings.at(d.name);
    if (t.contains("rate_hz") && !(settings.rate_hz > 0 && settings.rate_hz <= 4000)) {
      __builtin_trap();
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    Check(std::string(reinterpret_cast<const char*>(data), size));
  } catch (...) {
    __builtin_trap();
  }
  return 0;
}
