#include "daemon/service/options.h"

namespace turncal::daemon {

bool Options::IsValid(std::string* error) const {
  auto fail = [&](const std::string& message) {
    if (error) *error = message;
    return false;
  };
  if (once && replay_path.empty()) return fail("--once needs --replay FILE");
  if (!replay_path.empty() && !once) {
    return fail(
        "--replay needs --once (to replay a capture through the live service, give a device "
        "with PORT replay:FILE)");
  }
  if (!result_out.empty() && !once) return fail("--result-out needs --replay FILE --once");
  if (!record_path.empty() && once) return fail("--record is for live devices, not --once");
  if (replay_protocol && replay_path.empty()) return fail("--protocol needs --replay FILE");
  if (replay_rate_hz > 0 && !replay_protocol) {
    return fail("--rate is for a raw stream's replay (--replay FILE.bin --protocol P)");
  }
  for (std::size_t i = 0; i < devices.size(); ++i) {
    for (std::size_t j = i + 1; j < devices.size(); ++j) {
      if (devices[i].name == devices[j].name) {
        return fail("device name '" + devices[i].name + "' is given twice");
      }
    }
  }
  return true;
}

void AddCommandLine(CLI::App* app, Options* options) {
  app->add_option("--config", options->config_path, "configuration file (TOML)")
      ->check(CLI::ExistingFile);
  app->add_option_function<std::vector<std::string>>(
         "--device",
         [options](const std::vector<std::string>& specs) {
           for (const auto& text : specs) {
             std::string error;
             auto spec = drivers::ParseDeviceSpec(text, &error);
             if (!spec) throw CLI::ValidationError("--device", error);
             options->devices.push_back(*spec);
           }
         },
         "a device: NAME=PROTOCOL:PORT[@BAUD], PROTOCOL mip|gx2|xbus|xbus-legacy, PORT a path, "
         "tcp://HOST:PORT or replay:FILE (repeatable)")
      ->type_name("SPEC");
  app->add_option("--socket", options->socket_path, "Unix socket for clients")
      ->capture_default_str();
  app->add_option("--state-dir", options->state_dir,
                  "where calibrations and journals live (with --once: only when given here, and "
                  "a journal already there is resumed)")
      ->capture_default_str();
  app->add_option("--replay", options->replay_path, "run the pipeline on a capture (.tcap or .bin)")
      ->check(CLI::ExistingFile);
  app->add_option_function<std::string>(
         "--protocol",
         [options](const std::string& text) {
           auto p = drivers::ParseProtocol(text);
           if (!p) throw CLI::ValidationError("--protocol", "unknown protocol '" + text + "'");
           options->replay_protocol = p;
         },
         "protocol of a raw .bin replay: mip|gx2|xbus|xbus-legacy")
      ->type_name("P");
  app->add_option("--rate", options->replay_rate_hz,
                  "a raw replay's samples per second, for a stream without device time stamps")
      ->check(CLI::PositiveNumber);
  app->add_option("--pose-source", options->pose_source,
                  "announced (a controller announces each pose) or free (no table: the static "
                  "intervals of a tumble, calibrated with the free models accel9, gyro9, "
                  "magellipsoid, accmag); over [station] pose_source")
      ->check(CLI::IsMember({"announced", "free"}));
  app->add_flag("--once", options->once, "with --replay: process the whole capture, then exit");
  app->add_option("--result-out", options->result_out, "with --once: write the RESULT JSON here");
  app->add_option("--record", options->record_path,
                  "record every device's bytes and the pose commands into this capture (.tcap), "
                  "for `turncald --replay FILE --once`");
}

}  // namespace turncal::daemon
