// turncald: the calibration service. Thin main over turncal_daemon.

#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>

#include "daemon/config.h"
#include "daemon/journal_log.h"
#include "daemon/notify.h"
#include "daemon/options.h"
#include "daemon/replay_once.h"
#include "daemon/service.h"
#include "turncal/version.h"

int main(int argc, char** argv) {
  turncal::daemon::ConfigureLogging();
  CLI::App app{"turncald — turntable calibration service for inertial sensors", "turncald"};
  app.set_version_flag("--version", std::string("turncald ") + turncal::kVersion);
  turncal::daemon::Options options;
  turncal::daemon::AddCommandLine(&app, &options);
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
  if (options.once) {
    // The whole pipeline on a capture at full speed: events to stderr, the result to
    // --result-out (and a summary line per model).
    const turncal::daemon::StationOptions& station = config.station;
    turncal::daemon::ReplayOnceOutcome outcome;
    if (options.replay_protocol) {
      spdlog::error(
          "--replay with --once takes a .tcap capture (raw .bin streams: turncal decode)");
      return 2;
    }
    const bool ok = turncal::daemon::ReplayOnce(
        options.replay_path, station, options.result_out,
        [](const nlohmann::json& e) {
          const std::string kind = e.value("class", "");
          if (kind == "POSE_PROGRESS" || kind == "POSE_STARTED" || kind == "POSE_COLLECTING") {
            return;
          }
          spdlog::info("{}", e.dump());
        },
        &outcome, &error);
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
    }
    return 0;
  }
  // The service: devices, station, socket. SIGHUP re-reads the configuration file and applies
  // the same flags over it.
  const bool socket_flag = app.count("--socket") > 0;
  const bool state_flag = app.count("--state-dir") > 0;
  const turncal::daemon::Options flags = options;
  auto build = [flags, socket_flag, state_flag](turncal::daemon::ServiceOptions* out,
                                                std::string* why) {
    turncal::daemon::Config c;
    if (!flags.config_path.empty() && !turncal::daemon::LoadConfig(flags.config_path, &c, why)) {
      return false;
    }
    out->station = c.station;
    out->state_dir = c.state_dir && !state_flag ? *c.state_dir : flags.state_dir;
    out->socket.path = c.socket_path && !socket_flag ? *c.socket_path : flags.socket_path;
    out->socket.group = c.socket_group.value_or("");
    out->socket.control_uids = {c.control_uids.begin(), c.control_uids.end()};
    out->device_settings = c.device_settings;
    out->record_path = flags.record_path;
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
