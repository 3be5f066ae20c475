#pragma once
// turncald's configuration file (TOML; documented example: systemd/turncald.toml.example).
// Every key is checked: an unknown key, a wrong type or an impossible value is an error naming
// the key and its line, so a typo never silently falls back to a default.

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "daemon/live_device.h"
#include "daemon/station.h"
#include "drivers/device_spec.h"

namespace turncal::daemon {

struct Config {
  std::optional<std::string> socket_path;
  std::optional<std::string> state_dir;
  std::optional<std::string> socket_group;  // the socket's group (mode 0660)
  std::vector<unsigned> control_uids;       // may send pose, reset, publish (besides root, us)
  std::vector<drivers::DeviceSpec> devices;
  std::map<std::string, DeviceSettings> device_settings;  // by device name: rate_hz, configure
  StationOptions station;
};

// Parses `text` (named `source` in messages). False with a message on any error.
bool ParseConfig(const std::string& text, const std::string& source, Config* out,
                 std::string* error);
bool LoadConfig(const std::string& path, Config* out, std::string* error);

}  // namespace turncal::daemon
