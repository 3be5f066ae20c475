#include "tools/free_command.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/analysis/free_advice.h"
#include "core/estimation/free_calibrator.h"
#include "core/estimation/free_motion.h"
#include "core/estimation/sensor_class.h"
#include "core/sequencing/free_intervals.h"
#include "daemon/state/atomic_file.h"
#include "daemon/station/capture_replay.h"
#include "drivers/capture/raw_stream.h"
#include "drivers/capture/tcap.h"
#include "drivers/capture/text_log.h"
#include "drivers/decoder_factory.h"
#include "report/free_report.h"
#include "tools/help_text.h"

namespace turncal::tools {
namespace {

struct FreeArgs {
  std::vector<std::string> files;
  std::string format = "auto";
  std::string protocol;
  std::string device;
  std::string columns = "t,ax,ay,az,gx,gy,gz";
  double time_scale = 1.0;
  double rate_hz = 0.0;
  std::string sensor_class;
  std::string drift_class;
  drivers::TriadColumns acc, gyr, mag;  // offsets and scales only
  std::string models;
  FreeContext context;
  double dwell_s = 1.0;
  double max_dwell_s = 60.0;
  double min_coverage_percent = 0.0;
  bool intervals = false;
  bool still_only = false;
  int max_motion_points = MotionOptions{}.max_points;
  double mag_bandwidth_hz = 0.0;
  bool json = false;
  std::string html;
};

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Applies the per-triad offset and scale to decoded samples (text logs have their own).
void Rescale(const FreeArgs& a, std::vector<Sample>* samples) {
  for (Sample& s : *samples) {
    if (s.acc_mps2)
      s.acc_mps2 = (*s.acc_mps2 - Eigen::Vector3d::Constant(a.acc.offset)) * a.acc.scale;
    if (s.gyr_radps) {
      s.gyr_radps = (*s.gyr_radps - Eigen::Vector3d::Constant(a.gyr.offset)) * a.gyr.scale;
    }
    if (s.mag) s.mag = (*s.mag - Eigen::Vector3d::Constant(a.mag.offset)) * a.mag.scale;
  }
}

bool ReadSamples(const FreeArgs& a, std::vector<Sample>* out, std::string* source,
                 std::string* error) {
  std::string format = a.format;
  if (format == "auto") {
    format = a.files.size() == 2             ? "imu_tk"
             : EndsWith(a.files[0], ".tcap") ? "tcap"
             : !a.protocol.empty()           ? "raw"
                                             : "text";
  }
  if (format == "imu_tk") {
    if (a.files.size() != 2) {
      *error = "imu_tk's format is two files: the accelerometer's and the gyro's";
      return false;
    }
    drivers::TriadColumns acc = a.acc, gyr = a.gyr;
    drivers::TextLogStats stats;
    if (!drivers::ReadImuTkPair(a.files[0], a.files[1], acc, gyr, "imu_tk", out, &stats, error)) {
      return false;
    }
    *source = fmt::format(
        "imu_tk pair, {} samples at {:.1f} Hz{}", stats.samples, stats.rate_hz(),
        stats.skipped ? fmt::format(", {} lines skipped ({})", stats.skipped, stats.first_skipped)
                      : "");
    return true;
  }
  if (a.files.size() != 1) {
    *error = fmt::format("the {} format reads one file", format);
    return false;
  }
  if (format == "text") {
    drivers::TextLogLayout layout;
    if (!drivers::ParseColumnSpec(a.columns, &layout, error)) return false;
    layout.time_scale = a.time_scale;
    for (auto [t, from] :
         {std::pair{&layout.acc, &a.acc}, {&layout.gyr, &a.gyr}, {&layout.mag, &a.mag}}) {
      t->offset = from->offset;
      t->scale = from->scale;
    }
    drivers::TextLogStats stats;
    if (!drivers::ReadTextLogFile(a.files[0], layout, "text", out, &stats, error)) return false;
    *source = fmt::format(
        "text log, {} samples at {:.1f} Hz{}{}", stats.samples, stats.rate_hz(),
        stats.skipped
            ? fmt::format(", {} lines skipped (first: {})", stats.skipped, stats.first_skipped)
            : "",
        stats.backwards ? fmt::format(", {} going back in time dropped", stats.backwards) : "");
    return true;
  }
  std::vector<Sample> samples;
  if (format == "tcap") {
    drivers::CaptureReader reader;
    if (!reader.Open(a.files[0], error)) return false;
    int device = 0;
    if (!a.device.empty()) {
      device = -1;
      for (std::size_t i = 0; i < reader.header().devices.size(); ++i) {
        if (reader.header().devices[i].name == a.device) device = static_cast<int>(i);
      }
      if (device < 0) {
        *error = fmt::format("the capture has no device '{}'", a.device);
        return false;
      }
    }
    daemon::ReplayStats stats;
    if (!daemon::DecodeCaptureSamples(&reader, device, &samples, &stats, error)) return false;
    *source = fmt::format("capture, device {}, {} samples ({} pose events ignored: free mode)",
                          reader.header().devices.empty()
                              ? std::string("?")
                              : reader.header().devices[static_cast<std::size_t>(device)].name,
                          samples.size(), stats.pose_commands);
  } else if (format == "raw") {
    const auto protocol = drivers::ParseProtocol(a.protocol);
    if (!protocol) {
      *error = fmt::format("unknown protocol '{}' (mip, gx2, xbus, xbus-legacy)", a.protocol);
      return false;
    }
    drivers::RawStreamStats stats;
    if (!drivers::ReadRawStream(a.files[0], *protocol, a.rate_hz, &samples, &stats, error)) {
      if (error->find("carry no time") != std::string::npos) *error += ": --rate HZ";
      return false;
    }
    const auto& c = stats.decoder;
    *source = fmt::format("{} stream, {} samples, {} bad frames", a.protocol, samples.size(),
                          c.bad_checksums + c.bad_structure);
  } else {
    *error = fmt::format("unknown format '{}' (auto, tcap, raw, text, imu_tk)", format);
    return false;
  }
  Rescale(a, &samples);
  *out = std::move(samples);
  return true;
}

std::vector<std::string> Split(const std::string& list) {
  std::vector<std::string> out;
  std::stringstream ss(list);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

// The codes Run returns.
constexpr Manual kFreeManual = {
    "Calibrates without a turntable: a tumble by hand or on a fixture with unknown angles. "
    "The sequencer finds the static intervals itself (free mode: its stillness thresholds "
    "from the noise it measures, or from --sensor-class), then fits the free models -- "
    "accel9 (|f| = g), gyro9 (the gyro's turn between intervals against gravity's direction; "
    "gyro9g adds the g-sensitivity), magellipsoid (hard and soft iron; magsphere when the "
    "data cannot carry an ellipsoid, with the reason), accmag (the rotation between the "
    "magnetometer and the accelerometer from the constant dip) -- each with 1 sigma, the "
    "chi^2 fit check, the rank and its weakest direction, the spatial coverage (MicroStrain's "
    "18 x 32 bins), the gate and the next orientation to add. Inputs: a .tcap capture (its "
    "pose events ignored), a raw device stream (--protocol; --rate when it carries no "
    "clock), a text or CSV log (--columns, per-triad --*-offset and --*-scale), or imu_tk's "
    "two .mat files.",
    "turncal free tumble.tcap --intervals\n"
    "turncal free xsens_acc.mat xsens_gyro.mat --acc-offset 32768 --acc-scale 0.0026391 "
    "--gyr-offset 32768 --gyr-scale 0.0001598 --gravity 9.81744 --models accel9,gyro9g\n"
    "turncal free log.csv --columns t,ax,ay,az,mx,my,mz --field 0.5 --html report.html\n"
    "turncal free compass.bin --protocol mip --rate 50 --sensor-class consumer",
    "0 every model fitted and passed its gate; 1 a model was refused or could not be fitted; "
    "2 the input cannot be read or a command-line mistake",
    "docs/FREE.md, docs/ACCURACY.md (\"Without a turntable\")"};

int Run(const FreeArgs& a) {
  std::string error, source;
  std::vector<Sample> samples;
  if (!ReadSamples(a, &samples, &source, &error)) {
    fmt::print(stderr, "turncal free: {}\n", error);
    return 2;
  }
  if (samples.size() < 2) {
    fmt::print(stderr, "turncal free: {} samples: nothing to calibrate\n", samples.size());
    return 2;
  }
  if (const std::int64_t held = drivers::DropHeldRepeats(&samples)) {
    source += fmt::format(
        "; {} repeated magnetometer values dropped (the device holds its field "
        "between updates: {} new values remain)",
        held, samples.size());
  }
  SequencerOptions so;
  so.dwell_s = a.dwell_s;
  so.free_max_dwell_s = a.max_dwell_s;
  FreeContext context = a.context;
  if (!a.drift_class.empty()) {
    SensorClass sensor;
    if (!SensorClassByName(a.drift_class, &sensor)) {
      fmt::print(stderr, "turncal free: unknown sensor class '{}' (industrial, consumer)\n",
                 a.drift_class);
      return 2;
    }
    context.acc_drift = DriftForClass(sensor, SensorKind::kAccelerometer);
    context.mag_drift = DriftForClass(sensor, SensorKind::kMagnetometer);
    context.gyr_drift = DriftForClass(sensor, SensorKind::kGyroscope);
  }
  if (!a.sensor_class.empty()) {
    SensorClass sensor;
    if (!SensorClassByName(a.sensor_class, &sensor)) {
      fmt::print(stderr, "turncal free: unknown sensor class '{}' (industrial, consumer)\n",
                 a.sensor_class);
      return 2;
    }
    const double span = static_cast<double>(samples.back().t_host_ns - samples.front().t_host_ns);
    const double rate = span > 0 ? 1e9 * static_cast<double>(samples.size() - 1) / span : 0.0;
    so.noise = NoiseProfileForClass(sensor, rate, true);
    // The class's profile holds every triad; the stillness tests use those the stream carries.
    const Sample& first = samples.front();
    if (!first.acc_mps2) so.noise->sigma[kTriadAcc].reset();
    if (!first.gyr_radps) so.noise->sigma[kTriadGyr].reset();
    if (!first.mag) so.noise->sigma[kTriadMag].reset();
  }
  if (!so.IsValid(&error)) {
    fmt::print(stderr, "turncal free: {}\n", error);
    return 2;
  }
  // The still intervals, then the magnetometer's samples in motion (issue 37).
  MotionOptions mo;
  mo.max_points = a.max_motion_points;
  mo.mag_bandwidth_hz = a.mag_bandwidth_hz;
  FreeCollected collected = CollectFree(samples, so, a.still_only ? nullptr : &mo);
  const FreeIntervals& found = collected.found;
  const std::vector<FreeInterval>& data = collected.data;
  const std::optional<MotionPoints>& motion = collected.motion;

  const std::vector<std::string> models =
      a.models.empty() ? DefaultFreeModels(data) : Split(a.models);
  FreeCalibratorOptions co;
  co.min_coverage = a.min_coverage_percent / 100;
  if (motion) co.motion_noise_dof = motion->sigma_dof;
  std::vector<FreeModelResult> results;
  if (!CalibrateFreeModels(models, data, context, co, &results, &error)) {
    fmt::print(stderr, "turncal free: {}\n", error);
    return 2;
  }
  report::FreeReportInput input;
  input.source = source;
  input.found = found;
  input.motion = motion;
  input.context = context;
  input.results = results;
  input.advice = NextOrientations(results, data, context);
  bool all_passed = !results.empty();
  for (const auto& r : results) all_passed &= r.estimate.estimate.ok && r.estimate.gate_passed;
  if (!a.html.empty() &&
      !daemon::WriteFileAtomically(a.html, report::FreeReportHtml(input), &error)) {
    fmt::print(stderr, "turncal free: {}\n", error);
    return 2;
  }
  if (a.json) {
    fmt::print("{}\n", report::FreeReportJson(input).dump(2));
  } else {
    fmt::print("{}", report::FreeReportText(input, a.intervals));
    if (!a.html.empty()) fmt::print("report: {}\n", a.html);
  }
  return all_passed ? 0 : 1;
}

void AddTriadOptions(CLI::App* cmd, const char* name, drivers::TriadColumns* t, const char* unit) {
  cmd->add_option(fmt::format("--{}-offset", name), t->offset,
                  fmt::format("subtracted from the {} first (raw counts: the mid-scale)", name))
      ->capture_default_str();
  cmd->add_option(fmt::format("--{}-scale", name), t->scale,
                  fmt::format("then multiplied, to {}", unit))
      ->capture_default_str();
}

}  // namespace

void AddFreeCommand(CLI::App* app) {
  auto a = std::make_shared<FreeArgs>();
  auto* cmd = app->add_subcommand(
      "free",
      "Calibrate without a turntable (a tumble by hand or on a fixture): the static intervals, "
      "then accel9, gyro9, magellipsoid, accmag with sigma, coverage, gate and advice");
  SetManual(cmd, kFreeManual);
  cmd->add_option("files", a->files,
                  "a .tcap capture, a raw device stream (--protocol), a text/CSV log (--columns), "
                  "or imu_tk's two .mat files (accelerometer then gyro)")
      ->required()
      ->expected(1, 2);
  cmd->add_option("--format", a->format, "auto | tcap | raw | text | imu_tk")
      ->check(CLI::IsMember({"auto", "tcap", "raw", "text", "imu_tk"}))
      ->capture_default_str();
  cmd->add_option("--protocol", a->protocol, "raw streams: mip | gx2 | xbus | xbus-legacy");
  cmd->add_option("--device", a->device, "captures: the device (default: the first)");
  cmd->add_option("--rate", a->rate_hz, "raw streams without a device clock: samples per second")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--columns", a->columns,
                  "text logs: one name per column, t for the time, ax ay az / gx gy gz / mx my mz, "
                  "- to ignore")
      ->capture_default_str();
  cmd->add_option("--time-scale", a->time_scale, "text logs: the time column to seconds (1e-3: ms)")
      ->capture_default_str();
  AddTriadOptions(cmd, "acc", &a->acc, "m/s^2");
  AddTriadOptions(cmd, "gyr", &a->gyr, "rad/s");
  AddTriadOptions(cmd, "mag", &a->mag, "the field's unit");
  cmd->add_option("--models", a->models,
                  "comma-separated: accel9, gyro9, gyro9g, magellipsoid, magsphere, accmag "
                  "(default: what the data carry)");
  cmd->add_option("--gravity", a->context.gravity_mps2, "the local gravity, m/s^2")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--field", a->context.field_magnitude,
                  "the field's magnitude in the magnetometer's unit (0: unknown, the soft iron is "
                  "then relative)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--dip", a->context.dip_deg, "the field's dip, degrees (for the advice)")
      ->capture_default_str();
  cmd->add_option("--latitude", a->context.latitude_deg, "degrees north (the Earth's rate)")
      ->check(CLI::Range(-90.0, 90.0))
      ->capture_default_str();
  cmd->add_option("--drift", a->drift_class,
                  "each triad's bias drift as a process in time from a sensor class (industrial, "
                  "consumer; SENSORS.md): the terms correlated through it (generalised least "
                  "squares), the biases those over the latest interval")
      ->check(CLI::IsMember({"industrial", "consumer"}));
  cmd->add_option("--acc-offset-sigma", a->context.acc_offset_sigma,
                  "m/s^2 added to each interval's mean per axis (bias instability between them)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--gyr-offset-sigma", a->context.gyr_offset_sigma, "rad/s, likewise")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--mag-offset-sigma", a->context.mag_offset_sigma, "the field's unit, likewise")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--sensor-class", a->sensor_class,
                  "the stillness tests' noise from a sensor class (industrial, consumer; "
                  "SENSORS.md) instead of measuring it over the stream's first still second")
      ->check(CLI::IsMember({"industrial", "consumer"}));
  cmd->add_option("--dwell", a->dwell_s, "the shortest still segment taken, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--max-dwell", a->max_dwell_s, "the longest interval averaged, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--min-coverage", a->min_coverage_percent,
                  "the gate: the share of the 576 latitude-longitude bins required, percent")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  cmd->add_flag("--intervals", a->intervals, "list the static intervals found");
  cmd->add_flag("--still-only", a->still_only,
                "the static intervals only: leave out the magnetometer's samples in motion "
                "(taken by default: the field's magnitude holds while the device turns)");
  cmd->add_option("--max-motion-points", a->max_motion_points,
                  "at most this many magnetometer samples in motion (every k-th new value)")
      ->check(CLI::Range(10, 1000000))
      ->capture_default_str();
  cmd->add_option("--mag-bandwidth", a->mag_bandwidth_hz,
                  "the magnetometer's bandwidth, Hz, when known (its filter setting): the "
                  "samples in motion's expected magnitude is attenuated as a first-order "
                  "low-pass attenuates a turning field (0: not accounted for)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_flag("--json", a->json, "the result as JSON on stdout");
  cmd->add_option("--html", a->html, "write the report (with the coverage sphere) here");
  cmd->callback([a] { throw CLI::RuntimeError(Run(*a)); });
}

}  // namespace turncal::tools
