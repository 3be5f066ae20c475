// turncald: the calibration service. Thin main over turncal_daemon.

#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>

#include "daemon/service/config.h"
#include "daemon/service/notify.h"
#include "daemon/service/options.h"
#include "daemon/service/service.h"
#include "daemon/state/journal_log.h"
#include "daemon/station/replay_once.h"
#include "turncal/version.h"

namespace {

constexpr const char* kManual = R"(
DESCRIPTION
  Runs beside a turntable: reads the IMUs of the configuration (serial ports, ptys, TCP serial
  servers), collects stationary samples at every pose a controller announces on the socket,
  re-estimates the calibrations after each pose, and makes a calibration active (persisted in the
  state directory, announced, applied to the corrected output) once its gate passes. Flags
  override the configuration file; SIGHUP reloads it; SIGTERM stops cleanly. Under systemd it
  is Type=notify with a watchdog (systemd/turncald.service).
  --replay FILE --once runs the same pipeline on a capture at full speed and exits; a raw
  device stream (.bin) needs --protocol, and --rate when its samples carry no time.
  --pose-source free (or [station] pose_source = "free") needs no table and no controller: the
  sequencer finds the static intervals of a tumble by hand or on a fixture itself, and the free
  models (accel9, gyro9, gyro9g, magellipsoid, magsphere, accmag) calibrate from them
  (docs/FREE.md); pose events in a capture are then ignored.

EXAMPLES
  $ turncald --config /etc/turncal/turncald.toml
  $ turncald --device imu=mip:/dev/ttyUSB0@921600 --socket /tmp/t.sock --state-dir /tmp/state
  $ turncald --device a=mip:/dev/ttyUSB0 --device b=xbus:/dev/ttyUSB1@115200 --record s.tcap
  $ turncald --replay session.tcap --once --result-out result.json
  $ turncald --replay session.tcap --once --state-dir /tmp/replayed && \
    turncal report --state-dir /tmp/replayed -o report.html
  $ turncald --replay tumble.tcap --once --pose-source free --result-out result.json
  $ turncald --replay compass.bin --protocol mip --rate 50 --once --pose-source free

EXIT STATUS
  0 stopped by SIGTERM/SIGINT, or --once finished; 1 the service could not start (socket,
  state directory); 2 a command-line or configuration mistake (systemd does not restart it).

SEE ALSO
  systemd/turncald.toml.example (every configuration key), systemd/README.md (installing the
  service), docs/protocol.md (the socket), docs/TROUBLESHOOTING.md, turncal --help
)";

// --replay FILE --once: the whole pipeline on a capture at full speed, events to stderr, the
// result to --result-out and a summary line per model. Exit 0, or 2 when the capture cannot be
// replayed.
int RunOnce(const turncal::daemon::Options& options, const turncal::daemon::Config& config,
            bool state_flag) {
  std::string error;
  // The whole pipeline on a capture at full speed: events to stderr, the result to
  // --result-out (and a summary line per model).
  turncal::daemon::StationOptions station = config.station;
  if (!options.pose_source.empty()) {
    turncal::daemon::PoseSource source;
    turncal::daemon::ParsePoseSource(options.pose_source, &source);  // checked by CLI11
    turncal::daemon::ApplyPoseSource(source, config, &station);
  }
  // An explicit --state-dir makes the replay persist like the service (journal, noise, active
  // calibrations: what `turncal report --state-dir` reads); the configuration's state_dir and
  // the default are not used, so a replay never writes into the service's directory unasked.
  if (state_flag) station.state_dir = options.state_dir;
  turncal::daemon::ReplayOnceOutcome outcome;
  const auto on_event = [](const nlohmann::json& e) {
    const std::string kind = e.value("class", "");
    if (kind == "POSE_PROGRESS" || kind == "POSE_STARTED" || kind == "POSE_COLLECTING") return;
    spdlog::info("{}", e.dump());
  };
  const bool ok = options.replay_protocol
                      ? turncal::daemon::ReplayRawOnce(
                            options.replay_path, *options.replay_protocol, options.replay_rate_hz,
                            station, options.result_out, on_event, &outcome, &error)
                      : turncal::daemon::ReplayOnce(options.replay_path, station,
                                                    options.result_out, on_event, &outcome, &error);
  if (!ok) {
    spdlog::error("{}", error);
    return 2;
  }
  for (const auto& [device, d] : outcome.result["devices"].items()) {
    for (const auto& [model, m] : d["models"].items()) {
      spdlog::info("{} {}: {} poses, rank {}, gate {}{}", device, model, m["poses"].get<int>(),
                   m["rank"].get<int>(), m["gate"]["pass"].get<bool>() ? "pass" : "fail",
                   m["active_version"].get<int>() > 0 ? ", active" : "");
    }
    // A unit that does not sit as its mount says (issue 38): its calibrations were held.
    if (d.contains("mount") && !d["mount"]["check"]["ok"].get<bool>()) {
      spdlog::warn("{}: calibrations held: {}", device,
                   d["mount"]["check"]["problem"].get<std::string>());
    }
  }
  return 0;
}

// The service's options: the configuration file (read again at every SIGHUP), the flags over it.
// False with a message.
bool BuildServiceOptions(const turncal::daemon::Options& flags, bool socket_flag, bool state_flag,
                         turncal::daemon::ServiceOptions* out, std::string* why) {
  turncal::daemon::Config c;
  if (!flags.config_path.empty() && !turncal::daemon::LoadConfig(flags.config_path, &c, why)) {
    return false;
  }
  out->station = c.station;
  if (!flags.pose_source.empty()) {
    turncal::daemon::PoseSource source;
    turncal::daemon::ParsePoseSource(flags.pose_source, &source);  // checked by CLI11
    turncal::daemon::ApplyPoseSource(source, c, &out->station);
  }
  out->state_dir = c.state_dir && !state_flag ? *c.state_dir : flags.state_dir;
  out->socket.path = c.socket_path && !socket_flag ? *c.socket_path : flags.socket_path;
  out->socket.group = c.socket_group.value_or("");
  out->socket.control_uids = {c.control_uids.begin(), c.control_uids.end()};
  out->device_settings = c.device_settings;
  out->record_path = flags.record_path;
  out->registry = c.registry;
  out->devices = flags.devices;
  for (const auto& d : c.devices) {
    bool overridden = false;
    for (const auto& f : flags.devices) overridden = overridden || f.name == d.name;
    if (!overridden) out->devices.push_back(d);
  }
  if (out->devices.empty()) {
    *why = "no device: give --device NAME=PROTOCOL:PORT[@BAUD] or [[device]] in --config";
    return false;
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  turncal::daemon::ConfigureLogging();
  CLI::App app{"turncald — turntable calibration service for inertial sensors", "turncald"};
  app.set_version_flag("--version", std::string("turncald ") + turncal::kVersion);
  turncal::daemon::Options options;
  turncal::daemon::AddCommandLine(&app, &options);
  app.footer(kManual);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version exit 0; every command-line error exits 2 (systemd's
    // RestartPreventExitStatus=2: a configuration mistake is not retried).
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }

  std::string error;
  if (!options.IsValid(&error)) {
    spdlog::error("{}", error);
    return 2;
  }
  // The configuration file, then the flags over it.
  turncal::daemon::Config config;
  if (!options.config_path.empty() &&
      !turncal::daemon::LoadConfig(options.config_path, &config, &error)) {
    spdlog::error("{}", error);
    return 2;
  }
  if (config.socket_path && app.count("--socket") == 0) options.socket_path = *config.socket_path;
  if (config.state_dir && app.count("--state-dir") == 0) options.state_dir = *config.state_dir;
  for (const auto& d : config.devices) {
    bool overridden = false;
    for (const auto& f : options.devices) overridden = overridden || f.name == d.name;
    if (!overridden) options.devices.push_back(d);
  }
  if (options.once) return RunOnce(options, config, app.count("--state-dir") > 0);
  // The service: devices, station, socket. SIGHUP re-reads the configuration file and applies
  // the same flags over it.
  const bool socket_flag = app.count("--socket") > 0;
  const bool state_flag = app.count("--state-dir") > 0;
  const turncal::daemon::Options flags = options;
  auto build = [flags, socket_flag, state_flag](turncal::daemon::ServiceOptions* out,
                                                std::string* why) {
    return BuildServiceOptions(flags, socket_flag, state_flag, out, why);
  };
  turncal::daemon::ServiceOptions service_options;
  if (!build(&service_options, &error)) {
    spdlog::error("{}", error);
    return 2;
  }
  service_options.socket.activated_fd = turncal::daemon::ActivatedSocket();
  if (!options.config_path.empty()) service_options.reload = build;
  turncal::daemon::Service service(std::move(service_options));
  return service.Run();
}
