#include "tools/sim_command.h"

#include "core/frames/mount.h"

#include <fmt/format.h>

#include <cstdio>

#include <fcntl.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "core/frames/units.h"
#include "core/modeling/measurement_model.h"
#include "daemon/state/atomic_file.h"
#include "drivers/capture/tcap.h"
#include "protocol/pose_file.h"
#include "protocol/pose_json.h"
#include "sim/capture.h"
#include "sim/live.h"
#include "sim/session_sim.h"
#include "tools/help_text.h"
#include "tools/sim_options.h"
#include "tools/sim_thermal.h"

namespace turncal::tools {

namespace {

// "POSE:mid", "POSE:between", optionally ":DEVICE" (index among the --live devices).
bool ParseUnplug(const std::string& text, sim::LiveSimOptions::Unplug* u, std::string* error) {
  std::vector<std::string> parts;
  std::size_t at = 0;
  for (;;) {
    const std::size_t colon = text.find(':', at);
    parts.push_back(text.substr(at, colon == std::string::npos ? colon : colon - at));
    if (colon == std::string::npos) break;
    at = colon + 1;
  }
  auto number = [](const std::string& t, int* v) {
    if (t.empty() || t.size() > 6 || t.find_first_not_of("0123456789") != std::string::npos) {
      return false;
    }
    *v = std::stoi(t);
    return true;
  };
  if ((parts.size() != 2 && parts.size() != 3) || !number(parts[0], &u->pose) ||
      (parts[1] != "mid" && parts[1] != "between") ||
      (parts.size() == 3 && !number(parts[2], &u->device))) {
    *error = fmt::format("--unplug '{}': give POSE:mid or POSE:between, optionally :DEVICE", text);
    return false;
  }
  u->mid = parts[1] == "mid";
  return true;
}

// Writes the received bytes of `records` to `path` at their times (divided by `speed`), as a
// device would; pose events go to standard output as JSON lines at their times.
bool StreamLive(const std::string& path, const std::vector<drivers::CaptureRecord>& records,
                double speed, std::string* error) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_NOCTTY | O_CLOEXEC);
  if (fd < 0) {
    *error = fmt::format("cannot open '{}' for the live stream: {}", path, std::strerror(errno));
    return false;
  }
  termios t{};
  if (::tcgetattr(fd, &t) == 0) {
    ::cfmakeraw(&t);
    ::tcsetattr(fd, TCSANOW, &t);
  }
  const auto start = std::chrono::steady_clock::now();
  bool ok = true;
  for (const auto& r : records) {
    if (r.type == drivers::RecordType::kSent) continue;  // the host's side
    std::this_thread::sleep_until(start + std::chrono::nanoseconds(static_cast<std::int64_t>(
                                              static_cast<double>(r.t_ns) / speed)));
    if (r.type == drivers::RecordType::kEvent) {
      std::fwrite(r.payload.data(), 1, r.payload.size(), stdout);
      std::fputc('\n', stdout);
      std::fflush(stdout);
      continue;
    }
    std::size_t done = 0;
    while (done < r.payload.size()) {
      const ssize_t n = ::write(fd, r.payload.data() + done, r.payload.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        *error = fmt::format("writing to '{}': {}", path, std::strerror(errno));
        ok = false;
        break;
      }
      done += static_cast<std::size_t>(n);
    }
    if (!ok) break;
  }
  ::close(fd);
  return ok;
}

nlohmann::json TruthJson(const MeasurementModel& m, const Eigen::VectorXd& theta) {
  nlohmann::json j = nlohmann::json::object();
  for (int i = 0; i < m.num_parameters(); ++i) j[m.parameters()[i].name] = theta[i];
  return j;
}

std::vector<TablePose> WithRateSegments(const std::vector<TablePose>& poses,
                                        const std::vector<TablePose>& rates) {
  std::vector<TablePose> out;
  for (std::size_t i = 0; i < std::max(poses.size(), rates.size()); ++i) {
    if (i < poses.size()) out.push_back(poses[i]);
    if (i < rates.size()) out.push_back(rates[i]);
  }
  return out;
}

nlohmann::json TruthFor(const sim::SimCapture& capture, const std::vector<TablePose>& poses,
                        const SimCommandArgs& args) {
  std::string error;
  const SimulatedSession& session = capture.session;
  // The models about the unit's mount, as simulated (the truth's mounting angles are about it).
  ModelContext context;
  context.mounting = capture.mount;
  auto accel = MakeModel(capture.accel_model, context, &error);
  auto mag = MakeModel(capture.mag_model, context, &error);
  nlohmann::json pose_list = nlohmann::json::array();
  auto triad = [](const Eigen::Vector3d& v) { return nlohmann::json{v.x(), v.y(), v.z()}; };
  for (const auto& p : poses) {
    if (p.is_rate()) {
      pose_list.push_back(protocol::ToJson(p));
      continue;
    }
    // What a perfect correction outputs at this pose (noise-free, without the bias wander): the
    // true model's correction of its own prediction, in the models' output frames.
    const Eigen::Vector3d acc =
        accel->Correct(session.accel_truth, accel->Predict(session.accel_truth, p));
    const Eigen::Vector3d field =
        mag->Correct(session.mag_truth, mag->Predict(session.mag_truth, p));
    pose_list.push_back({{"phi_deg", p.phi_rad * kDegPerRad},
                         {"gamma_deg", p.gamma_rad * kDegPerRad},
                         {"psi_deg", p.psi_rad * kDegPerRad},
                         {"true_output", {{"acc", triad(acc)}, {"mag", triad(field)}}}});
  }
  // What each reported parameter estimates: the bias parameters are the bias over the last
  // pose's dwell (the turn-on bias plus the wander there: "bias_truth": "at_last_pose"), which is
  // what the drift-aware calibrator reports (docs/ACCURACY.md "Drift").
  Eigen::VectorXd accel_truth = session.accel_truth, mag_truth = session.mag_truth;
  accel_truth.tail<3>() += session.LastPoseAccBiasOffset();
  mag_truth.tail<3>() += session.LastPoseMagBiasOffset();
  const SessionSimOptions& so = capture.session_options;
  nlohmann::json models = {{capture.accel_model, TruthJson(*accel, accel_truth)},
                           {capture.mag_model, TruthJson(*mag, mag_truth)}};
  nlohmann::json turn_on = {{capture.accel_model, triad(session.accel_truth.tail<3>())},
                            {capture.mag_model, triad(session.mag_truth.tail<3>())}};
  if (!capture.gyro_model.empty()) {
    auto gyro = MakeModel(capture.gyro_model, context, &error);
    Eigen::VectorXd gyro_truth = session.gyro_truth;
    const int b = gyro->index_of("bx");
    if (!session.events.empty()) gyro_truth.segment<3>(b) += session.events.back().gyr_wander_mean;
    models[capture.gyro_model] = TruthJson(*gyro, gyro_truth);
    turn_on[capture.gyro_model] = triad(session.gyro_truth.segment<3>(b));
  }
  nlohmann::json truth = {
      {"acc_bias_instability", so.sensor.acc_bias_instability},
      {"mag_bias_instability", so.sensor.mag_bias_instability},
      {"bias_tau_s", so.sensor.bias_tau_s},
      {"acc_random_walk", so.acc_random_walk},
      {"mag_random_walk", so.mag_random_walk},
      {"acc_warmup", so.acc_warmup},
      {"mag_warmup", so.mag_warmup},
      {"gyr_warmup", so.gyr_warmup},
      {"warmup_tau_s", so.warmup_tau_s},
      {"bias_truth", "at_last_pose"},
      {"models", models},
      {"turn_on_bias", turn_on},
      {"gyr_bias_instability", so.sensor.gyr_bias_instability},
      {"latitude_deg", ReferenceVectors{}.latitude_deg},
      {"gyro_bias_radps",
       {session.gyro_bias_radps.x(), session.gyro_bias_radps.y(), session.gyro_bias_radps.z()}},
      {"class", args.sensor_class},
      {"protocol", args.protocol},
      {"seed", args.seed},
      {"lever_arm_m", args.lever_arm_m},
      {"gyr_nonlinearity_ppm_per_dps", args.gyr_nonlinearity_ppm_per_dps},
      {"rate_hz", capture.session_options.rate_hz},
      {"dwell_s", capture.session_options.dwell_s},
      {"move_s", capture.session_options.table ? nlohmann::json("at the table's rates")
                                               : nlohmann::json(capture.session_options.move_s)},
      {"table_rate_dps",
       capture.session_options.table ? capture.session_options.table->rate_dps[0] : 0.0},
      {"duration_s", session.duration_s},
      {"mount", MountConfigText(capture.mount)},
      {"samples", session.samples.size()},
      {"poses", pose_list}};
  if (so.chamber) truth["thermal"] = ThermalTruthJson(capture);
  return truth;
}

// The codes RunController and RunSim return.
constexpr Manual kSimManual = {
    "Simulates a whole turntable session: a .tcap capture of a MIP, GX2 or Xbus device and a "
    "truth file. With --live it streams into ptys in real time (or --live-speed times "
    "faster); with --controller it also plays the lab's controller on turncald's socket.",
    "turncal sim --protocol mip --seed 1 --truth-out truth.json -o session.tcap\n"
    "turncal sim --protocol xbus --live /tmp/imu --poses poses.csv --live-speed 2\n"
    "turncal sim --protocol mip --protocol xbus --live /tmp/a /tmp/b --controller "
    "/run/turncal/turncal.sock",
    "0 written (with --controller: every pose captured); 1 some pose was not captured or a "
    "write failed; 2 a command-line mistake",
    "docs/SIMULATOR.md"};

// One simulated device per --live, each with its protocol and seed (the first's + i), and each
// one's truth; 0, or the code to return.
int BuildLiveDevices(const SimCommandArgs& args, const sim::SimCaptureOptions& options,
                     std::vector<sim::LiveSimDevice>* devices, nlohmann::json* truths) {
  std::string error;
  for (std::size_t i = 0; i < args.lives.size(); ++i) {
    const std::string& name = args.protocols[std::min(i, args.protocols.size() - 1)];
    const auto protocol = drivers::ParseProtocol(name);
    if (!protocol) {
      fmt::print(stderr, "turncal sim: unknown protocol '{}' (mip, gx2, xbus, xbus-legacy)\n",
                 name);
      return 2;
    }
    sim::SimCaptureOptions o = options;
    o.protocol = *protocol;
    o.session.seed = options.session.seed + i;
    if (!args.mounts.empty()) {
      ParseMountText(args.mounts[std::min(i, args.mounts.size() - 1)], &o.mount, nullptr);
    }
    sim::LiveSimDevice d;
    d.path = args.lives[i];
    if (!sim::BuildSimCapture(o, &d.capture, &error)) {
      fmt::print(stderr, "turncal sim: {}\n", error);
      return 2;
    }
    SimCommandArgs a = args;
    a.protocol = name;
    a.seed = o.session.seed;
    nlohmann::json t = TruthFor(d.capture, o.poses, a);
    t["live"] = d.path;
    truths->push_back(t);
    devices->push_back(std::move(d));
  }
  return 0;
}

// The live session's options from the command line; 0, or the code to return.
int LiveOptionsFor(const SimCommandArgs& args, sim::LiveSimOptions* live) {
  live->speed = args.live_speed;
  live->controller = args.controller;
  live->answer_timeout_s = args.answer_timeout_s;
  live->retries = args.retries;
  live->bit_error_rate = args.bit_error_rate;
  live->fault_seed = args.seed * 7919 + 17;
  live->unplug_s = args.unplug_s;
  live->device_state_dir = args.device_state;
  live->hold_end_s = args.hold_end_s;
  live->serials = args.serials;
  if (!live->device_state_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(live->device_state_dir, ec);
    if (ec) {
      fmt::print(stderr, "turncal sim: cannot create '{}': {}\n", live->device_state_dir,
                 ec.message());
      return 1;
    }
  }
  for (const auto& text : args.lose_replies) {
    unsigned descriptor = 0, function = 0;
    char tail = 0;
    if (std::sscanf(text.c_str(), "%x:%u%c", &descriptor, &function, &tail) != 2 ||
        descriptor > 0xFF || function < 1 || function > 5) {
      fmt::print(stderr,
                 "turncal sim: --lose-reply '{}': DESC:FUNCTION, e.g. 0x3B:3 (the first save of "
                 "the soft iron)\n",
                 text);
      return 2;
    }
    live->lose_replies.push_back(
        {static_cast<std::uint8_t>(descriptor), static_cast<std::uint8_t>(function)});
  }
  std::string error;
  for (const auto& text : args.unplugs) {
    sim::LiveSimOptions::Unplug u;
    if (!ParseUnplug(text, &u, &error)) {
      fmt::print(stderr, "turncal sim: {}\n", error);
      return 2;
    }
    live->unplugs.push_back(u);
  }
  return 0;
}

// The live session's outcome: a line on standard error, and the same as a JSON line on standard
// output with the line faults' figures.
void PrintLiveSummary(const SimCommandArgs& args, const std::vector<sim::LiveSimDevice>& devices,
                      const sim::LiveSimReport& report) {
  std::string frames;
  for (std::size_t i = 0; i < devices.size(); ++i) {
    frames += fmt::format("{}{}: {} frames sent, {} withheld (idle/config), {} dropped (unread)",
                          i ? "; " : "", devices[i].path, report.frames_sent[i],
                          report.frames_withheld[i], report.frames_dropped[i]);
  }
  fmt::print(stderr,
             "turncal sim: {} poses, {} captured by every device, {} given up, {} reconnects, "
             "table held {:.1f} s past the planned dwells; {}\n",
             report.poses, report.captured, report.unanswered, report.reconnects, report.held_s,
             frames);
  // The same as a JSON line on standard output, with the line faults' figures: a test accounts
  // for every byte (the daemon's bytes_read of a device equals its bytes_written here).
  nlohmann::json summary = {{"event", "summary"},
                            {"poses", report.poses},
                            {"captured", report.captured},
                            {"given_up", report.unanswered},
                            {"reconnects", report.reconnects},
                            {"bit_error_rate", args.bit_error_rate}};
  for (std::size_t i = 0; i < devices.size(); ++i) {
    summary["devices"].push_back({{"live", devices[i].path},
                                  {"frames_sent", report.frames_sent[i]},
                                  {"frames_withheld", report.frames_withheld[i]},
                                  {"frames_dropped", report.frames_dropped[i]},
                                  {"bytes_written", report.bytes_written[i]},
                                  {"bits_flipped", report.bits_flipped[i]},
                                  {"unplugs", report.unplugs[i]},
                                  {"frames_unplugged", report.frames_unplugged[i]},
                                  {"bytes_lost_unplugged", report.bytes_lost_unplugged[i]}});
  }
  fmt::print("{}\n", summary.dump());
  std::fflush(stdout);
}

int RunController(const SimCommandArgs& args, const sim::SimCaptureOptions& options) {
  std::vector<sim::LiveSimDevice> devices;
  nlohmann::json truths = nlohmann::json::array();
  if (const int code = BuildLiveDevices(args, options, &devices, &truths); code != 0) return code;
  std::string error;
  if (!args.truth_out.empty()) {
    // Written before the session starts, so a test can read it while the session runs.
    nlohmann::json truth = truths[0];
    truth["devices"] = truths;
    if (!daemon::WriteFileAtomically(args.truth_out, truth.dump(2) + "\n", &error)) {
      fmt::print(stderr, "turncal sim: {}\n", error);
      return 1;
    }
  }
  sim::LiveSimOptions live;
  if (const int code = LiveOptionsFor(args, &live); code != 0) return code;
  sim::LiveSimReport report;
  if (!sim::RunLiveSim(&devices, live, &report, &error)) {
    fmt::print(stderr, "turncal sim: {}\n", error);
    return 1;
  }
  PrintLiveSummary(args, devices, report);
  return report.captured == report.poses ? 0 : 1;
}

// The models (each to its sensor's slot) and the poses (the file's, or the default ones, with
// the default rate segments for a gyro model unless the poses hold their own); 0, or the code
// to return.
int ReadModelsAndPoses(const SimCommandArgs& args, sim::SimCaptureOptions* options) {
  std::string error;
  for (const auto& m : args.models) {
    auto model = MakeModel(m, ModelContext{}, &error);
    if (!model) {
      fmt::print(stderr, "turncal sim: {}\n", error);
      return 2;
    }
    if (m == "mag-physical") {
      fmt::print(stderr, "turncal sim: mag-physical is for the observability demonstration only\n");
      return 2;
    }
    (model->sensor() == SensorKind::kAccelerometer ? options->accel_model
     : model->sensor() == SensorKind::kGyroscope   ? options->gyro_model
                                                   : options->mag_model) = m;
  }

  if (!args.poses_file.empty()) {
    std::ifstream in(args.poses_file, std::ios::binary);
    std::stringstream text;
    text << in.rdbuf();
    if (!in || !ParsePoses(text.str(), &options->poses, &error)) {
      fmt::print(stderr, "turncal sim: {}: {}\n", args.poses_file, in ? error : "cannot open");
      return 2;
    }
  }
  const bool has_rates = std::any_of(options->poses.begin(), options->poses.end(),
                                     [](const TablePose& p) { return p.is_rate(); });
  if (!options->gyro_model.empty() && !has_rates && !args.no_rate_segments) {
    // What a gyro model needs besides the static poses: rate segments, one after each of the
    // first poses (DefaultRateSegments), unless the poses hold their own.
    options->poses = WithRateSegments(options->poses, DefaultRateSegments());
  }
  return 0;
}

// The session's sensor class with the command line's overrides, its drift, table, times and
// seed; the capture's link and faults.
void SetSessionOptions(const SimCommandArgs& args, sim::SimCaptureOptions* options) {
  SessionSimOptions& o = options->session;
  SensorClassByName(args.sensor_class, &o.sensor);
  if (args.acc_noise >= 0) o.sensor.acc_noise_density = args.acc_noise;
  if (args.acc_bias_instability >= 0) o.sensor.acc_bias_instability = args.acc_bias_instability;
  if (args.gyr_noise >= 0) o.sensor.gyr_noise_density = args.gyr_noise;
  if (args.mag_noise >= 0) o.sensor.mag_noise_rms = args.mag_noise;
  if (args.mag_bias_instability >= 0) o.sensor.mag_bias_instability = args.mag_bias_instability;
  if (args.bias_tau_s > 0) o.sensor.bias_tau_s = args.bias_tau_s;
  o.acc_random_walk = args.acc_random_walk;
  o.mag_random_walk = args.mag_random_walk;
  o.acc_warmup = args.acc_warmup;
  o.mag_warmup = args.mag_warmup;
  o.gyr_warmup = args.gyr_warmup;
  o.warmup_tau_s = args.warmup_tau_s;
  if (args.table_rate_dps > 0) {
    TableMotion table;
    table.rate_dps.setConstant(args.table_rate_dps);
    table.accel_dps2.setConstant(args.table_accel_dps2);
    table.settle_s = o.settle_s;
    o.table = table;
  }
  if (args.no_quantisation) o.sensor.acc_quantum = o.sensor.gyr_quantum = o.sensor.mag_quantum = 0;
  o.rate_hz = args.rate_hz;  // <= 0: the protocol's default
  o.dwell_s = args.dwell_s;
  if (args.lever_arm_m.size() == 3) {
    o.lever_arm_q_m =
        Eigen::Vector3d(args.lever_arm_m[0], args.lever_arm_m[1], args.lever_arm_m[2]);
  }
  // ppm per deg/s -> relative per rad/s.
  o.gyr_scale_nonlinearity = args.gyr_nonlinearity_ppm_per_dps * 1e-6 * kDegPerRad;
  o.seed = args.seed;
  if (args.start_s >= 0) {
    o.start_s = args.start_s;
  } else if (!args.lives.empty() && !args.controller.empty() && !(args.hand_s > 0)) {
    // Driven by a controller, the table rests at home until the daemon has measured the noise
    // (turncald's first second of samples, on its own clock), streaming the rest's samples again
    // should it take longer. A rest of 1 device second is then seen over and over at any
    // --live-speed above 1: the daemon's second of 10 at --live-speed 10 held the same 100 values
    // ten times, measured sigma from 100 and claimed 1000 degrees of freedom (issue 38: the start-
    // up sigmas of 8 units scattered by 9 %, and one unit's still limit was 17 % tight). So the
    // rest lasts 3 s of wall time: fresh samples for a daemon started up to 2 s after the
    // simulator.
    o.start_s = std::max(o.start_s, 3.0 * args.live_speed);
  }
  o.mag_rate_hz = args.mag_rate_hz;
  o.mag_bandwidth_hz = args.mag_bandwidth_hz;
  o.mag_lag_s = args.mag_lag_s;
  o.mag_noise_filtered = args.mag_noise_filtered;
  if (args.magnet_at_s >= 0) {
    o.magnet_at_s = args.magnet_at_s;
    o.magnet_s = args.magnet_s;
    o.magnet_peak = args.magnet_peak;
  }
  if (args.hand_s > 0) {
    sim::HandMotion hand;
    hand.duration_s = args.hand_s;
    hand.rate_dps = args.hand_rate_dps;
    sim::HandPathByName(args.hand_path, &hand.path);
    hand.pause_every_s = args.hand_pause_every_s;
    hand.pause_s = args.hand_pause_s;
    o.hand = hand;
    options->poses.clear();
  }
  options->baud = args.baud;
  options->faults = args.faults;
  options->burst_ms = args.burst_ms;
}

// What was written, on standard error: the faults injected and the session's size.
void PrintCaptureSummary(const SimCommandArgs& args, const sim::SimCaptureOptions& options,
                         const sim::SimCapture& capture) {
  if (args.faults) {
    const sim::SimFaultReport& f = capture.faults;
    const std::string early =
        f.early_pose_index < 0
            ? std::string()
            : fmt::format(", pose {} announced {} s early, {} s before the move ends",
                          f.early_pose_index, f.early_s,
                          f.early_s - capture.session_options.settle_s);
    fmt::print(stderr,
               "turncal sim: faults: {} bit flips, {} dropped bytes, sample {} saturated{}\n",
               f.bit_flips, f.dropped_bytes, f.saturated_index, early);
  }
  fmt::print(stderr, "turncal sim: {} poses, {} samples at {} Hz, {:.1f} s, {} records -> {}\n",
             options.poses.size(), capture.session.samples.size(), capture.session_options.rate_hz,
             capture.session.duration_s, capture.records.size(), args.output);
}

// The capture to -o and/or streamed to --live, and the truth file.
int WriteCapture(const SimCommandArgs& args, const sim::SimCaptureOptions& options) {
  std::string error;
  sim::SimCapture capture;
  if (!sim::BuildSimCapture(options, &capture, &error)) {
    fmt::print(stderr, "turncal sim: {}\n", error);
    return 2;
  }
  if (!args.output.empty() && !sim::WriteSimCapture(capture, args.output, &error)) {
    fmt::print(stderr, "turncal sim: {}\n", error);
    return 1;
  }
  if (!args.live.empty() && !StreamLive(args.live, capture.records, args.live_speed, &error)) {
    fmt::print(stderr, "turncal sim: {}\n", error);
    return 1;
  }
  if (!args.truth_out.empty()) {
    const nlohmann::json truth = TruthFor(capture, options.poses, args);
    if (!daemon::WriteFileAtomically(args.truth_out, truth.dump(2) + "\n", &error)) {
      fmt::print(stderr, "turncal sim: {}\n", error);
      return 1;
    }
  }
  PrintCaptureSummary(args, options, capture);
  return 0;
}

int RunSim(const SimCommandArgs& args) {
  const auto protocol = drivers::ParseProtocol(args.protocol);
  if (!protocol) {
    fmt::print(stderr, "turncal sim: unknown protocol '{}' (mip, gx2, xbus, xbus-legacy)\n",
               args.protocol);
    return 2;
  }
  sim::SimCaptureOptions options;
  options.protocol = *protocol;
  // Checked by ValidateSimArgs.
  if (!args.mounts.empty()) ParseMountText(args.mounts.front(), &options.mount, nullptr);
  if (const int code = ReadModelsAndPoses(args, &options); code != 0) return code;
  SetSessionOptions(args, &options);
  if (std::string error; !ApplyChamberArgs(args, &options.session, &error)) {
    fmt::print(stderr, "turncal sim: {}\n", error);
    return 2;
  }
  if (!args.controller.empty()) return RunController(args, options);
  return WriteCapture(args, options);
}

}  // namespace

void AddSimCommand(CLI::App* app) {
  auto args = std::make_shared<SimCommandArgs>();
  auto* cmd = app->add_subcommand(
      "sim", "simulate a complete turntable session as a .tcap capture with a truth file");
  SetManual(cmd, kSimManual);
  AddSimCommandOptions(cmd, args.get());
  cmd->callback([args] {
    ValidateSimArgs(args.get());
    throw CLI::RuntimeError(RunSim(*args));
  });
}

}  // namespace turncal::tools
