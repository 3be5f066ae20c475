#include "tools/characterise_command.h"

#include <fmt/format.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "daemon/state/atomic_file.h"
#include "drivers/transport/transport.h"
#include "protocol/noise_json.h"
#include "report/characterisation.h"
#include "tools/help_text.h"
#include "tools/noise_input.h"
#include "tools/report_state_dir.h"

namespace turncal::tools {
namespace {

struct CharacteriseArgs {
  std::vector<std::string> calibrations;
  std::string state_dir;
  std::string device;
  std::vector<std::string> noise;
  std::vector<std::string> noise_triad;  // per --noise (text columns)
  std::vector<double> noise_scale;       // per --noise (text columns)
  std::string noise_protocol;
  double noise_to_s = INFINITY;
  std::string output;
  bool json = false;
};

// A calibration document, or `turncal free --json`'s output (its "models").
bool AddCalibrationFile(const std::string& path, report::CharacterisationInput* in,
                        std::string* error) {
  nlohmann::json j;
  if (!daemon::ReadJsonFile(path, &j, error)) return false;
  if (j.is_object() && j.contains("models") && j["models"].is_array()) {
    for (const auto& m : j["models"]) {
      in->calibrations.push_back(m);
      in->calibration_sources.push_back(path);
    }
    return true;
  }
  if (!j.is_object() || !j.contains("model")) {
    *error =
        fmt::format("{}: neither a calibration document nor `turncal free --json` output", path);
    return false;
  }
  in->calibrations.push_back(j);
  in->calibration_sources.push_back(path);
  return true;
}

// A rest measurement: JSON with "axes" (turncal noise --json, a rest_noise/ file), or a
// recording analysed here as `turncal noise` would.
bool AddNoise(const CharacteriseArgs& a, std::size_t index, report::CharacterisationInput* in,
              std::string* error) {
  const std::string& path = a.noise[index];
  nlohmann::json axes;
  if (std::filesystem::path(path).extension() == ".json") {
    nlohmann::json j;
    if (!daemon::ReadJsonFile(path, &j, error)) return false;
    if (!j.contains("axes") || !j["axes"].is_array()) {
      *error = fmt::format("{}: no \"axes\" (turncal noise --json's output or a rest_noise/ file)",
                           path);
      return false;
    }
    axes = j["axes"];
  } else {
    NoiseInputArgs n;
    n.file = path;
    n.protocol = a.noise_protocol;
    if (index < a.noise_triad.size()) n.text_triads = {a.noise_triad[index]};
    if (index < a.noise_scale.size()) n.text_scale = a.noise_scale[index];
    n.to_s = a.noise_to_s;
    n.progress = "never";
    NoiseInput input;
    if (ReadNoiseInput(n, &input) != 0) {
      *error = fmt::format("{} cannot be read as a rest recording", path);
      return false;
    }
    const std::vector<RestNoiseAxis> results = AnalyseRestNoise(input.noise);
    if (results.empty()) {
      *error = fmt::format("{} has no triad with enough samples", path);
      return false;
    }
    axes = RestNoiseAxesJson(results);
  }
  for (nlohmann::json axis : axes) {
    axis["source"] = path;  // each row names the recording it came from
    in->noise_axes.push_back(axis);
  }
  in->noise_sources.push_back(path);
  return true;
}

// The newest rest_noise/DEVICE.*.json of a state directory, if any.
std::string NewestRestNoise(const std::string& state_dir, const std::string& device) {
  const std::filesystem::path dir = std::filesystem::path(state_dir) / "rest_noise";
  std::error_code ec;
  std::vector<std::string> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(device + ".", 0) == 0 && entry.path().extension() == ".json")
      files.push_back(entry.path().string());
  }
  std::sort(files.begin(), files.end());
  return files.empty() ? "" : files.back();
}

int Run(const CharacteriseArgs& args) {
  auto fail = [](const std::string& message, int code) {
    fmt::print(stderr, "turncal characterise: {}\n", message);
    return code;
  };
  if (args.calibrations.empty() && args.state_dir.empty() && args.noise.empty()) {
    return fail("give calibrations, --state-dir or --noise (turncal characterise --help)", 2);
  }
  report::CharacterisationInput in;
  in.generated_utc = drivers::UtcNowIso8601();
  std::string error;
  CharacteriseArgs a = args;
  if (!args.state_dir.empty()) {
    std::map<std::string, DeviceCalibrations> devices;
    if (!ReadStateDirCalibrations(args.state_dir, args.device, &devices, &error))
      return fail(error, 2);
    if (devices.size() > 1) {
      std::string names;
      for (const auto& [name, d] : devices) names += (names.empty() ? "" : ", ") + name;
      return fail(fmt::format("{} holds several devices ({}): choose one with --device",
                              args.state_dir, names),
                  2);
    }
    const auto& [device, d] = *devices.begin();
    for (std::size_t i = 0; i < d.calibrations.size(); ++i) {
      nlohmann::json doc = d.calibrations[i];
      AttachJournalRecords(args.state_dir, &doc);
      in.calibrations.push_back(doc);
      in.calibration_sources.push_back(d.paths[i]);
    }
    if (a.noise.empty()) {
      const std::string rest = NewestRestNoise(args.state_dir, device);
      if (!rest.empty()) a.noise.push_back(rest);
    }
  }
  for (const std::string& path : args.calibrations)
    if (!AddCalibrationFile(path, &in, &error)) return fail(error, 2);
  for (std::size_t i = 0; i < a.noise.size(); ++i)
    if (!AddNoise(a, i, &in, &error)) return fail(error, 2);
  report::Characterisation c;
  if (!report::Characterise(in, &c, &error)) return fail(error, 2);
  if (!args.output.empty()) {
    if (!daemon::WriteFileAtomically(args.output, report::CharacterisationHtml(c), &error))
      return fail(error, 1);
  }
  if (args.json) {
    nlohmann::json j = report::ToJson(c);
    if (!args.output.empty()) j["file"] = args.output;
    fmt::print("{}\n", j.dump());
  } else {
    fmt::print("{}", report::CharacterisationText(c));
    if (!args.output.empty()) fmt::print("\nreport: {}\n", args.output);
  }
  return 0;
}

constexpr Manual kManual = {
    "The IEEE test report: what IEEE Std 1293 (accelerometers), 952 and 1431 (gyroscopes) ask a "
    "lab to measure, item by item, with the figure this session measured and its expanded "
    "uncertainty U (k = 2), or its 95 % interval where that is skewed (a standard deviation, a "
    "noise coefficient) -- or, for an item the session could not measure, why not and what "
    "would measure it. From calibrations: bias, scale factor, non-orthogonality and "
    "misalignment, the accelerometer's K2 (accel15), the gyroscope's g-sensitivity (gyro21, "
    "gyro9g), its scale factor's non-linearity and asymmetry (a turntable session's rate "
    "segments). From several sessions' calibrations: the bias's turn-on repeatability (the "
    "scatter beyond each estimate's sigma, with its chi^2 interval). From a rest recording "
    "(--noise, analysed as `turncal noise` does, or its JSON): IEEE 952's Q, N, B, K, R and the "
    "warm-up time (the transient from the first sample down to the Allan floor). --state-dir "
    "takes a daemon's active calibrations and its newest rest_noise/ file.",
    "turncal characterise --state-dir /var/lib/turncald -o ieee.html\n"
    "turncal characterise day1/imu.gyro21.json day2/imu.gyro21.json --noise rest.tcap\n"
    "turncal free xsens_acc.mat xsens_gyro.mat ... --json > free.json\n"
    "turncal characterise free.json --noise xsens_acc.mat --noise-triad acc --noise-scale "
    "0.0026391 --noise xsens_gyro.mat --noise-triad gyr --noise-scale 0.0001598 --noise-to 45 "
    "-o imu_tk.html",
    "0 the report was made; 1 it cannot be written; 2 an input cannot be read or a command-line "
    "mistake",
    "docs/CHARACTERISE.md, docs/NOISE.md, docs/REGISTRY.md (\"Drift\")"};

}  // namespace

void AddCharacteriseCommand(CLI::App* app) {
  auto args = std::make_shared<CharacteriseArgs>();
  CLI::App* cmd = app->add_subcommand(
      "characterise",
      "The IEEE test report (1293, 952, 1431): each item measured with U (k = 2), "
      "or why not");
  SetManual(cmd, kManual);
  cmd->add_option("calibrations", args->calibrations,
                  "calibration documents (calibrations/DEVICE.MODEL.json), or `turncal free "
                  "--json` output; several sessions' give the turn-on repeatability");
  cmd->add_option("--state-dir", args->state_dir,
                  "a state directory: its active calibrations and newest rest_noise/ file");
  cmd->add_option("--device", args->device, "with --state-dir: the device (when it holds several)");
  cmd->add_option("--noise", args->noise,
                  "a rest recording (capture, raw stream, text columns, .npy; from switch-on "
                  "for the warm-up) or its `turncal noise --json`; repeatable")
      ->allow_extra_args(false);
  cmd->add_option("--noise-triad", args->noise_triad,
                  "per --noise, text columns: acc | gyr | mag (the columns t x y z)")
      ->check(CLI::IsMember({"acc", "gyr", "mag"}))
      ->allow_extra_args(false);
  cmd->add_option("--noise-scale", args->noise_scale,
                  "per --noise, text columns: multiply the values by this (counts to SI)")
      ->allow_extra_args(false);
  cmd->add_option("--noise-protocol", args->noise_protocol,
                  "raw streams: mip | gx2 | xbus | xbus-legacy");
  cmd->add_option("--noise-to", args->noise_to_s,
                  "seconds from the first sample to stop at (the rest only)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("-o,--output", args->output, "write the HTML report here");
  cmd->add_flag("--json", args->json, "the report as JSON on stdout");
  cmd->callback([args] { throw CLI::RuntimeError(Run(*args)); });
}

}  // namespace turncal::tools
