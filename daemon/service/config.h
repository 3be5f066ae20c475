#pragma once
// turncald's configuration file (TOML; documented example: systemd/turncald.toml.example).
// Every key is checked: an unknown key, a wrong type or an impossible value is an error naming
// the key and its line, so a typo never silently falls back to a default.

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "daemon/device/live_device.h"
#include "daemon/registry/registry_options.h"
#include "daemon/service/config_fixture.h"
#include "daemon/station/station.h"
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
  bool models_set = false;   // [station] models was given (else the pose source's default)
  bool dwell_set = false;    // [sequencer] dwell_s was given
  RegistryOptions registry;  // [registry] (daemon/registry/registry_options.h); no conninfo: none
  Fixture fixture;           // [fixture] (daemon/service/config_fixture.h); no slots: none
};

// Parses `text` (named `source` in messages). False with a message on any error.
bool ParseConfig(const std::string& text, const std::string& source, Config* out,
                 std::string* error);
bool LoadConfig(const std::string& path, Config* out, std::string* error);

// The pose source (the file's [station] pose_source, or turncald --pose-source over it). Free mode
// without a configured model list estimates what the data carry (the pose models' default list is
// dropped), and without a configured [sequencer] dwell_s takes every still segment of at least
// kFreeDwellS (a hand's rest is short; the table's default dwell is 3 s).
void ApplyPoseSource(PoseSource source, const Config& config, StationOptions* station);
inline constexpr double kFreeDwellS = 1.0;

}  // namespace turncal::daemon
