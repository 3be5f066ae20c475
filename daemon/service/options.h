#pragma once
// turncald's command line (DESIGN.md "Command line"). Flags override the configuration file.

#include <CLI/CLI.hpp>
#include <optional>
#include <string>
#include <vector>

#include "drivers/device_spec.h"

namespace turncal::daemon {

struct Options {
  std::string config_path;                   // --config FILE (TOML)
  std::vector<drivers::DeviceSpec> devices;  // --device NAME=PROTOCOL:PORT[@BAUD]
  std::string socket_path = "/run/turncal/turncal.sock";
  std::string state_dir = "/var/lib/turncal";
  std::string replay_path;                           // --replay FILE
  std::optional<drivers::Protocol> replay_protocol;  // --protocol, for raw .bin replays
  double replay_rate_hz = 0.0;  // --rate: a raw replay's sample rate when it carries no time
  bool once = false;            // --once: run the capture, then exit
  std::string result_out;       // --result-out FILE
  std::string record_path;      // --record FILE.tcap: every device's bytes and the pose commands
  // --pose-source announced|free: over [station] pose_source ("free": no table, the sequencer
  // finds the static intervals itself and the free models calibrate, docs/FREE.md).
  std::string pose_source;

  // False with a message when the combination of flags cannot run.
  bool IsValid(std::string* error) const;
};

// Adds turncald's flags to `app`, storing into `options`. Device and protocol strings are parsed
// and checked by CLI11 validators, so a bad flag is an error before anything starts.
void AddCommandLine(CLI::App* app, Options* options);

}  // namespace turncal::daemon
