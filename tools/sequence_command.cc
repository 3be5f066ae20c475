#include "tools/sequence_command.h"

#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "daemon/station/capture_replay.h"
#include "protocol/pose_file.h"
#include "protocol/sequencer_json.h"
#include "sim/synthetic.h"
#include "tools/help_text.h"

namespace turncal::tools {
namespace {

struct SequenceArgs {
  std::string file;
  std::string schedule;
  std::string noise_class;  // empty: measured at start-up
  double dwell_s = SequencerOptions{}.dwell_s;
  double window_s = StillnessOptions{}.window_s;
  double settle_guard_s = SequencerOptions{}.settle_guard_s;
  double timeout_s = SequencerOptions{}.still_timeout_s;
  double startup_s = NoiseMeterOptions{}.duration_s;
  double max_bad = SequencerOptions{}.max_bad_fraction;
  double max_lost = SequencerOptions{}.max_lost_fraction;
  double false_alarm = StillnessOptions{}.false_alarm;
  double check_angle_deg = 0;  // 0: no pose check
  bool progress = false;
  bool json = false;
};

std::string PoseText(const TablePose& p) {
  return fmt::format("({:.1f}, {:.1f}, {:.1f}) deg", p.phi_rad * 180 / M_PI,
                     p.gamma_rad * 180 / M_PI, p.psi_rad * 180 / M_PI);
}

// The codes RunSequence returns.
constexpr Manual kSequenceManual = {
    "Replays a capture through the decoders and the position sequencer only: which poses were "
    "captured or rejected, and why. Useful to tune stillness settings on a real recording.",
    "turncal sequence session.tcap\n"
    "turncal sequence table.tcap --schedule poses.csv --dwell 5 --json",
    "0; 2 the capture cannot be read or a command-line mistake", "docs/SEQUENCER.md"};

int RunSequence(const SequenceArgs& args) {
  daemon::ReplayOptions options;
  SequencerOptions& o = options.sequencer;
  o.dwell_s = args.dwell_s;
  o.settle_guard_s = args.settle_guard_s;
  o.still_timeout_s = args.timeout_s;
  o.max_bad_fraction = args.max_bad;
  o.max_lost_fraction = args.max_lost;
  o.stillness.window_s = args.window_s;
  o.stillness.false_alarm = args.false_alarm;
  o.noise_meter.duration_s = args.startup_s;
  drivers::CaptureReader reader;
  std::string error;
  if (!reader.Open(args.file, &error)) {
    fmt::print(stderr, "turncal sequence: {}\n", error);
    return 2;
  }
  if (!args.noise_class.empty()) {
    SensorClass c;
    if (!SensorClassByName(args.noise_class, &c)) {
      fmt::print(stderr, "turncal sequence: unknown class '{}' (industrial, consumer)\n",
                 args.noise_class);
      return 2;
    }
    // The configured profile needs the rate: the simulator's note says it; otherwise the
    // class's nominal rate.
    double rate = c.rate_hz;
    const auto& note = reader.header().note;
    if (const auto at = note.find("--rate "); at != std::string::npos) {
      rate = std::atof(note.c_str() + at + 7);
    }
    o.noise = NoiseProfileForClass(c, rate, true);
  }
  if (!args.schedule.empty()) {
    std::ifstream in(args.schedule, std::ios::binary);
    std::stringstream text;
    text << in.rdbuf();
    std::vector<TablePose> poses;
    if (!in || !ParsePoses(text.str(), &poses, &error)) {
      fmt::print(stderr, "turncal sequence: {}: {}\n", args.schedule, in ? error : "cannot open");
      return 2;
    }
    options.schedule = poses;
  }
  if (!o.IsValid(&error)) {
    fmt::print(stderr, "turncal sequence: {}\n", error);
    return 2;
  }
  std::vector<std::unique_ptr<MeasurementModel>> models;
  if (args.check_angle_deg > 0) {
    models.push_back(MakeModel("accel13", ModelContext{}, &error));
    const MeasurementModel* accel = models.back().get();
    const double angle = args.check_angle_deg * M_PI / 180;
    const double false_alarm = o.pose_check_false_alarm;
    options.predictor = [accel, angle, false_alarm](const TablePose& pose,
                                                    int triad) -> std::optional<TriadPrediction> {
      if (triad != kTriadAcc) return std::nullopt;
      return NominalPrediction(*accel, pose, angle, false_alarm);
    };
  }
  const auto& devices = reader.header().devices;
  auto print = [&](int device, const SequencerEvent& e) {
    if (e.kind == SequencerEventKind::kProgress && !args.progress) return;
    if (args.json) {
      nlohmann::json j = protocol::ToJson(e);
      j["device"] = devices[static_cast<std::size_t>(device)].name;
      fmt::print("{}\n", j.dump());
      return;
    }
    std::string line =
        fmt::format("{:9.3f} s  {:<8} {:<16}", e.t_s,
                    devices[static_cast<std::size_t>(device)].name, ToString(e.kind));
    if (e.kind != SequencerEventKind::kNoiseMeasured && e.kind != SequencerEventKind::kNoiseRetry) {
      line += fmt::format(" pose {} {}", e.index, PoseText(e.pose));
    }
    if (e.kind == SequencerEventKind::kProgress) {
      line += fmt::format(" {}/{}", e.collected, e.needed);
    }
    if (e.kind == SequencerEventKind::kCaptured && e.record && e.record->acc) {
      const auto& a = *e.record->acc;
      line += fmt::format(
          " acc [{:.5f} {:.5f} {:.5f}] m/s^2, {} samples, {} lost, {} flagged, "
          "{} outliers",
          a.mean.x(), a.mean.y(), a.mean.z(), a.count, e.counts.lost, e.counts.flagged,
          e.counts.outliers);
    } else if (!e.reason.empty()) {
      line += ": " + e.reason;
    }
    fmt::print("{}\n", line);
  };
  daemon::ReplayResult result;
  if (!daemon::ReplayCapture(&reader, options, &result, &error, print)) {
    fmt::print(stderr, "turncal sequence: {}\n", error);
    return 2;
  }
  for (const auto& w : result.warnings) fmt::print(stderr, "turncal sequence: {}\n", w);
  for (const auto& d : result.devices) {
    std::int64_t captured = 0, rejected = 0, skipped = 0;
    SampleCounts in_poses;  // over the captured windows
    for (const auto& e : d.events) {
      captured += e.kind == SequencerEventKind::kCaptured;
      rejected += e.kind == SequencerEventKind::kRejected;
      skipped += e.kind == SequencerEventKind::kSegmentSkipped;
      if (e.kind == SequencerEventKind::kCaptured) {
        in_poses.used += e.counts.used;
        in_poses.flagged += e.counts.flagged;
        in_poses.outliers += e.counts.outliers;
        in_poses.lost += e.counts.lost;
      }
    }
    if (args.json) {
      fmt::print("{}\n", nlohmann::json{{"class", "SEQUENCE_SUMMARY"},
                                        {"device", d.name},
                                        {"pose_commands", result.pose_commands},
                                        {"captured", captured},
                                        {"rejected", rejected},
                                        {"segments_skipped", skipped},
                                        {"samples_used", d.totals.used},
                                        {"in_poses",
                                         {{"flagged", in_poses.flagged},
                                          {"outliers", in_poses.outliers},
                                          {"lost", in_poses.lost}}},
                                        {"stream",
                                         {{"flagged", d.totals.flagged},
                                          {"outliers", d.totals.outliers},
                                          {"lost", d.totals.lost}}},
                                        {"bad_checksums", d.decoder.bad_checksums}}
                             .dump());
    } else {
      fmt::print(
          "SUMMARY {}: {} pose commands, {} captured, {} rejected, {} segments skipped; {} "
          "samples used; in the captured windows {} flagged, {} outliers, {} lost; whole stream "
          "(motion included) {} flagged, {} outliers, {} lost; decoder: {} frames, {} bad "
          "checksums\n",
          d.name, result.pose_commands, captured, rejected, skipped, d.totals.used,
          in_poses.flagged, in_poses.outliers, in_poses.lost, d.totals.flagged, d.totals.outliers,
          d.totals.lost, d.decoder.frames, d.decoder.bad_checksums);
    }
  }
  return 0;
}

}  // namespace

void AddSequenceCommand(CLI::App* app) {
  auto args = std::make_shared<SequenceArgs>();
  auto* cmd = app->add_subcommand(
      "sequence",
      "replay a capture through the decoders and the position sequencer: which poses were "
      "captured or rejected, and why");
  SetManual(cmd, kSequenceManual);
  cmd->add_option("file", args->file, "a .tcap capture")->required();
  cmd->add_option("--schedule", args->schedule,
                  "schedule mode: poses in order (JSON or CSV, degrees) assigned to still "
                  "segments; the capture's pose events are ignored");
  cmd->add_option("--dwell", args->dwell_s, "seconds of samples to average per pose")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--window", args->window_s, "stillness window, seconds")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--settle-guard", args->settle_guard_s,
                  "stillness required beyond one window before samples count, seconds")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--timeout", args->timeout_s,
                  "seconds after an announcement to wait for stillness")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--startup", args->startup_s,
                  "seconds of the stream's start used to measure the noise (table at rest)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--noise-class", args->noise_class,
                  "take the noise from a datasheet class (industrial, consumer) instead of "
                  "measuring it");
  cmd->add_option("--max-bad", args->max_bad,
                  "largest fraction of flagged and outlier samples in a pose")
      ->check(CLI::Range(0.0, 0.99))
      ->capture_default_str();
  cmd->add_option("--max-lost", args->max_lost,
                  "fraction of a dwell's samples that may be lost (counter gaps) before the pose "
                  "is rejected")
      ->capture_default_str();
  cmd->add_option("--false-alarm", args->false_alarm,
                  "probability that one stillness test calls a still window moving")
      ->check(CLI::Range(1e-15, 0.1))
      ->capture_default_str();
  cmd->add_option("--check-angle", args->check_angle_deg,
                  "reject a pose whose gravity direction is more than this many degrees from "
                  "the nominal prediction for the announced angles (0: no check)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_flag("--progress", args->progress, "also print progress events");
  cmd->add_flag("--json", args->json, "one JSON object a line (the daemon's event shapes)");
  cmd->callback([args] { throw CLI::RuntimeError(RunSequence(*args)); });
}

}  // namespace turncal::tools
