#include "tools/sim_command.h"

#include <fmt/format.h>

#include <fcntl.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "core/reference.h"
#include "core/session_sim.h"
#include "drivers/capture/tcap.h"
#include "drivers/gx2/gx2_encoder.h"
#include "drivers/mip/mip_encoder.h"
#include "drivers/xbus/xbus_encoder.h"
#include "protocol/pose_file.h"

namespace turncal::tools {

namespace {

using Bytes = std::vector<std::uint8_t>;
constexpr double kRadToDeg = 180.0 / M_PI;

struct Args {
  std::string protocol;
  std::vector<std::string> models = {"accel13", "mag13"};
  std::string poses_file;
  std::uint64_t seed = 1;
  double dwell_s = 5.0;
  double rate_hz = 0.0;  // 0: the protocol's default
  int baud = 0;          // 0: the protocol's default
  std::string sensor_class = "industrial";
  std::string truth_out;
  std::string output;
  double burst_ms = 16.0;
  bool faults = false;
  // Overrides of the class's noise (negative: the class's value).
  double acc_noise = -1, acc_bias_instability = -1, gyr_noise = -1, mag_noise = -1,
         mag_bias_instability = -1;
  bool no_quantisation = false;
  std::string live;  // a pty (or any writable tty/file) to stream to at real time
  double live_speed = 1.0;
};

struct ProtocolDefaults {
  double rate_hz;
  int baud;
  int bits_per_byte;  // 10 for 8N1, 11 for 8N2
};

ProtocolDefaults Defaults(drivers::Protocol p) {
  switch (p) {
    case drivers::Protocol::kMip:
      return {500.0, 921600, 10};
    case drivers::Protocol::kGx2:
      return {100.0, 115200, 10};
    case drivers::Protocol::kXbus:
      return {100.0, 115200, 10};
    case drivers::Protocol::kXbusLegacy:
      return {100.0, 115200, 11};
  }
  return {100.0, 115200, 10};
}

const drivers::XbusLegacyLayout kLegacyLayout{0x0003, 0x00000001};  // temp, calibrated, counter

Bytes Encode(drivers::Protocol p, const Sample& s) {
  switch (p) {
    case drivers::Protocol::kMip: {
      Sample m = s;
      m.counter.reset();
      return drivers::mip::SensorPacket(m);
    }
    case drivers::Protocol::kGx2:
      return drivers::gx2::Reply(0xCB, s, {});
    case drivers::Protocol::kXbus:
      return drivers::xbus::MtData2(s);
    case drivers::Protocol::kXbusLegacy:
      return drivers::xbus::MtData(s, kLegacyLayout);
  }
  return {};
}

// What the host sends and the device answers before the stream starts.
std::vector<std::pair<Bytes, Bytes>> StartUp(drivers::Protocol p, std::uint64_t seed, double rate,
                                             double base_rate) {
  namespace mip = drivers::mip;
  namespace xbus = drivers::xbus;
  std::vector<std::pair<Bytes, Bytes>> out;
  switch (p) {
    case drivers::Protocol::kMip: {
      out.push_back({mip::SetToIdle(), mip::Reply(0x01, 0x02, 0)});
      Bytes info;
      info.push_back(0x04);
      info.push_back(0xD2);
      for (std::string s : {std::string("3DM-GX5-25 sim"), std::string("6251-4220"),
                            fmt::format("SIM.{}", seed), std::string("sim"), std::string("")}) {
        s.resize(16, ' ');
        info.insert(info.end(), s.begin(), s.end());
      }
      const mip::Field info_field{0x81, info};
      out.push_back({mip::GetDeviceInfo(), mip::Reply(0x01, 0x03, 0, {&info_field, 1})});
      const auto base = static_cast<std::uint16_t>(base_rate);
      const mip::Field rate_field{
          0x83, {static_cast<std::uint8_t>(base >> 8), static_cast<std::uint8_t>(base)}};
      out.push_back({mip::GetImuBaseRate(), mip::Reply(0x0C, 0x06, 0, {&rate_field, 1})});
      const auto dec = static_cast<std::uint16_t>(std::lround(base_rate / rate));
      const std::pair<std::uint8_t, std::uint16_t> format[] = {
          {0x04, dec}, {0x05, dec}, {0x06, dec}};
      out.push_back({mip::ImuMessageFormat(format), mip::Reply(0x0C, 0x08, 0)});
      out.push_back({mip::EnableStream(0x80, true), mip::Reply(0x0C, 0x11, 0)});
      out.push_back({mip::Resume(), mip::Reply(0x01, 0x06, 0)});
      break;
    }
    case drivers::Protocol::kXbus: {
      out.push_back({xbus::Message(xbus::kGoToConfig), xbus::Message(xbus::kGoToConfigAck)});
      out.push_back({xbus::Message(xbus::kReqDid),
                     xbus::Message(xbus::kDeviceId, Bytes{0x03, 0x78, 0x00, 0x01})});
      const auto r = static_cast<std::uint16_t>(rate);
      const std::pair<std::uint16_t, std::uint16_t> outputs[] = {
          {xbus::kPacketCounter, 0xFFFF}, {xbus::kSampleTimeFine, 0xFFFF},
          {xbus::kTemperature, r},        {xbus::kAcceleration, r},
          {xbus::kRateOfTurn, r},         {xbus::kMagneticField, r}};
      const Bytes set = xbus::SetOutputConfiguration(outputs);
      out.push_back(
          {set, xbus::Message(xbus::kOutputConfiguration,
                              std::span<const std::uint8_t>(set).subspan(4, set.size() - 5))});
      out.push_back(
          {xbus::Message(xbus::kGoToMeasurement), xbus::Message(xbus::kGoToMeasurementAck)});
      break;
    }
    case drivers::Protocol::kXbusLegacy: {
      out.push_back({xbus::Message(xbus::kGoToConfig), xbus::Message(xbus::kGoToConfigAck)});
      out.push_back({xbus::Message(xbus::kReqOutputMode),
                     xbus::Message(xbus::kReqOutputMode + 1, Bytes{0x00, 0x03})});
      out.push_back({xbus::Message(xbus::kReqOutputSettings),
                     xbus::Message(xbus::kReqOutputSettings + 1, Bytes{0x00, 0x00, 0x00, 0x01})});
      out.push_back(
          {xbus::Message(xbus::kGoToMeasurement), xbus::Message(xbus::kGoToMeasurementAck)});
      break;
    }
    case drivers::Protocol::kGx2:
      out.push_back({drivers::gx2::StartContinuous(0xCB), drivers::gx2::ContinuousAck(0xCB, 0)});
      break;
  }
  return out;
}

bool WriteAtomically(const std::string& path, const std::string& text, std::string* error) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out || !(out << text) || !out.flush()) {
      *error = "cannot write '" + tmp + "'";
      return false;
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    *error = "cannot rename '" + tmp + "' to '" + path + "': " + ec.message();
    return false;
  }
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

int Run(const Args& args) {
  const auto protocol = drivers::ParseProtocol(args.protocol);
  if (!protocol) {
    fmt::print(stderr, "turncal sim: unknown protocol '{}' (mip, gx2, xbus, xbus-legacy)\n",
               args.protocol);
    return 2;
  }
  std::string accel_name = "accel13", mag_name = "mag13", error;
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
    (model->sensor() == SensorKind::kAccelerometer ? accel_name : mag_name) = m;
  }
  auto accel = MakeModel(accel_name, ModelContext{}, &error);
  auto mag = MakeModel(mag_name, ModelContext{}, &error);

  std::vector<TablePose> poses = DefaultSessionPoses();
  if (!args.poses_file.empty()) {
    std::ifstream in(args.poses_file, std::ios::binary);
    std::stringstream text;
    text << in.rdbuf();
    if (!in || !ParsePoses(text.str(), &poses, &error)) {
      fmt::print(stderr, "turncal sim: {}: {}\n", args.poses_file, in ? error : "cannot open");
      return 2;
    }
  }
  const ProtocolDefaults d = Defaults(*protocol);
  SessionSimOptions o;
  SensorClassByName(args.sensor_class, &o.sensor);
  if (args.acc_noise >= 0) o.sensor.acc_noise_density = args.acc_noise;
  if (args.acc_bias_instability >= 0) o.sensor.acc_bias_instability = args.acc_bias_instability;
  if (args.gyr_noise >= 0) o.sensor.gyr_noise_density = args.gyr_noise;
  if (args.mag_noise >= 0) o.sensor.mag_noise_rms = args.mag_noise;
  if (args.mag_bias_instability >= 0) o.sensor.mag_bias_instability = args.mag_bias_instability;
  if (args.no_quantisation) o.sensor.acc_quantum = o.sensor.gyr_quantum = o.sensor.mag_quantum = 0;
  o.rate_hz = args.rate_hz > 0 ? args.rate_hz : d.rate_hz;
  o.dwell_s = args.dwell_s;
  o.seed = args.seed;
  if (!o.IsValid(&error)) {
    fmt::print(stderr, "turncal sim: {}\n", error);
    return 2;
  }
  const int baud = args.baud > 0 ? args.baud : d.baud;
  // The link budget (SENSORS.md): rate x frame size must fit in baud / bits-per-byte.
  Sample probe;
  probe.t_device_s = 1.0;
  probe.counter = 1;
  probe.acc_mps2 = probe.gyr_radps = probe.mag = Eigen::Vector3d::Zero();
  probe.temp_c = 25.0;
  const double frame_bytes = static_cast<double>(Encode(*protocol, probe).size());
  const double capacity = static_cast<double>(baud) / d.bits_per_byte;
  if (frame_bytes * o.rate_hz > capacity) {
    fmt::print(stderr,
               "turncal sim: {} frames of {} bytes at {} Hz need {:.0f} bytes/s, more than {} "
               "baud carries ({:.0f} bytes/s): lower --rate or raise --baud\n",
               args.protocol, frame_bytes, o.rate_hz, frame_bytes * o.rate_hz, baud, capacity);
    return 2;
  }

  const SimulatedSession session = SimulateSession(*accel, *mag, poses, o);

  drivers::CaptureHeader header;
  drivers::CaptureDevice device{"imu", *protocol, baud, std::nullopt, std::nullopt};
  if (*protocol == drivers::Protocol::kXbusLegacy) {
    device.output_mode = kLegacyLayout.output_mode;
    device.output_settings = kLegacyLayout.output_settings;
  }
  header.devices.push_back(device);
  header.created = "simulated";
  header.note = fmt::format(
      "turncal sim --protocol {} --model {} --model {} --class {} --seed {} --rate {} --dwell {} "
      "(acc noise {} m/s^2/sqrt(Hz), acc bias instability {} m/s^2, gyr noise {} rad/s/sqrt(Hz), "
      "mag noise {} G, mag bias instability {} G, quantisation {}{})",
      args.protocol, accel_name, mag_name, args.sensor_class, args.seed, o.rate_hz, o.dwell_s,
      o.sensor.acc_noise_density, o.sensor.acc_bias_instability, o.sensor.gyr_noise_density,
      o.sensor.mag_noise_rms, o.sensor.mag_bias_instability,
      o.sensor.acc_quantum > 0 ? "16-bit" : "none", args.faults ? ", faults" : "");
  std::vector<drivers::CaptureRecord> records;
  auto append = [&](drivers::RecordType type, std::uint64_t at,
                    std::span<const std::uint8_t> payload) {
    records.push_back({type, 0, at, Bytes(payload.begin(), payload.end())});
    return true;
  };
  bool ok = true;
  // Faults on request: a bit flip about every 500th frame, a dropped byte about every 700th, one
  // saturated sample, and one pose announced half a second before the table settled.
  std::mt19937_64 fault_rng(args.seed ^ 0x5eedfa17ull);
  std::uniform_int_distribution<int> one_in(0, 999999);
  const std::size_t saturated_index = session.samples.size() / 3;
  int faults_flips = 0, faults_drops = 0;
  std::uint64_t t_ns = 0;
  for (const auto& [sent, reply] : StartUp(*protocol, args.seed, o.rate_hz, 1000.0)) {
    ok = ok && append(drivers::RecordType::kSent, t_ns, sent);
    t_ns += 2'000'000;
    ok = ok && append(drivers::RecordType::kReceived, t_ns, reply);
    t_ns += 2'000'000;
  }
  const auto offset_ns = static_cast<std::int64_t>(t_ns);
  Bytes burst;
  std::int64_t burst_start = -1;
  const auto burst_ns = static_cast<std::int64_t>(args.burst_ms * 1e6);
  std::size_t next_event = 0;
  auto flush = [&](std::int64_t at) {
    if (!burst.empty()) {
      ok = ok && append(drivers::RecordType::kReceived, static_cast<std::uint64_t>(at), burst);
      burst.clear();
    }
    burst_start = -1;
  };
  auto emit_events_until = [&](std::int64_t at) {
    while (next_event < session.events.size() &&
           offset_ns +
                   static_cast<std::int64_t>(std::llround(session.events[next_event].t_s * 1e9)) <=
               at) {
      const auto& e = session.events[next_event++];
      // --faults: the second pose is announced half a second before the table has settled.
      const double early = args.faults && e.index == 1 ? 0.5 : 0.0;
      const auto te = offset_ns + static_cast<std::int64_t>(std::llround((e.t_s - early) * 1e9));
      flush(te);
      const std::string event = nlohmann::json{
          {"event", "pose"},
          {"index", e.index},
          {"phi_deg", e.pose.phi_rad * kRadToDeg},
          {"gamma_deg", e.pose.gamma_rad * kRadToDeg},
          {"psi_deg", e.pose.psi_rad * kRadToDeg},
          {"dwell_s", o.dwell_s}}.dump();
      ok = ok && append(drivers::RecordType::kEvent, static_cast<std::uint64_t>(te),
                        Bytes(event.begin(), event.end()));
    }
  };
  for (std::size_t k = 0; k < session.samples.size(); ++k) {
    Sample s = session.samples[k];
    const std::int64_t at = offset_ns + s.t_host_ns;
    emit_events_until(at);
    if (burst_start >= 0 && at - burst_start >= burst_ns) flush(at);
    if (burst_start < 0) burst_start = at;
    if (args.faults && k == saturated_index) {
      // A saturated sample: the accelerometer clips at its range on x.
      s.acc_mps2->x() = 16 * kStandardGravity_mps2;
      s.flags |= kAccSaturated;
    }
    Bytes frame = Encode(*protocol, s);
    if (args.faults && one_in(fault_rng) < 2000) {
      const auto byte = static_cast<std::size_t>(one_in(fault_rng)) % frame.size();
      frame[byte] ^= static_cast<std::uint8_t>(1u << (one_in(fault_rng) % 8));
      ++faults_flips;
    }
    if (args.faults && one_in(fault_rng) < 1430) {
      frame.erase(frame.begin() +
                  static_cast<long>(static_cast<std::size_t>(one_in(fault_rng)) % frame.size()));
      ++faults_drops;
    }
    burst.insert(burst.end(), frame.begin(), frame.end());
    if (!ok) break;
  }
  const auto end_ns = offset_ns + static_cast<std::int64_t>(std::llround(session.duration_s * 1e9));
  flush(end_ns);
  emit_events_until(end_ns);
  const std::string end_event = R"({"event":"end"})";
  ok = ok && append(drivers::RecordType::kEvent, static_cast<std::uint64_t>(end_ns),
                    Bytes(end_event.begin(), end_event.end()));
  if (!args.output.empty()) {
    auto writer = drivers::CaptureWriter::Create(args.output, header, &error);
    ok = writer != nullptr;
    for (std::size_t i = 0; ok && i < records.size(); ++i) {
      const auto& r = records[i];
      ok = writer->Append(r.type, r.device, r.t_ns, r.payload, &error);
    }
    if (!ok || !writer->Close(&error)) {
      fmt::print(stderr, "turncal sim: {}\n", error);
      return 1;
    }
  }
  if (!args.live.empty() && !StreamLive(args.live, records, args.live_speed, &error)) {
    fmt::print(stderr, "turncal sim: {}\n", error);
    return 1;
  }

  if (!args.truth_out.empty()) {
    nlohmann::json pose_list = nlohmann::json::array();
    for (const auto& p : poses) {
      pose_list.push_back({{"phi_deg", p.phi_rad * kRadToDeg},
                           {"gamma_deg", p.gamma_rad * kRadToDeg},
                           {"psi_deg", p.psi_rad * kRadToDeg}});
    }
    const nlohmann::json truth = {
        {"models",
         {{accel_name, TruthJson(*accel, session.accel_truth)},
          {mag_name, TruthJson(*mag, session.mag_truth)}}},
        {"gyro_bias_radps",
         {session.gyro_bias_radps.x(), session.gyro_bias_radps.y(), session.gyro_bias_radps.z()}},
        // The biases in "models" are turn-on biases; a calibration over the session also sees the
        // slow bias wander averaged over the dwells, given here (add it to bx, by, bz).
        {"accel_bias_wander_mean",
         {session.EffectiveAccBiasOffset().x(), session.EffectiveAccBiasOffset().y(),
          session.EffectiveAccBiasOffset().z()}},
        {"mag_bias_wander_mean",
         {session.EffectiveMagBiasOffset().x(), session.EffectiveMagBiasOffset().y(),
          session.EffectiveMagBiasOffset().z()}},
        {"class", args.sensor_class},
        {"protocol", args.protocol},
        {"seed", args.seed},
        {"rate_hz", o.rate_hz},
        {"dwell_s", o.dwell_s},
        {"samples", session.samples.size()},
        {"poses", pose_list}};
    if (!WriteAtomically(args.truth_out, truth.dump(2) + "\n", &error)) {
      fmt::print(stderr, "turncal sim: {}\n", error);
      return 1;
    }
  }
  if (args.faults) {
    fmt::print(stderr,
               "turncal sim: faults: {} bit flips, {} dropped bytes, sample {} saturated, pose 1 "
               "announced 0.5 s early\n",
               faults_flips, faults_drops, saturated_index);
  }
  fmt::print(stderr, "turncal sim: {} poses, {} samples at {} Hz, {:.1f} s, {} records -> {}\n",
             poses.size(), session.samples.size(), o.rate_hz, session.duration_s, records.size(),
             args.output);
  return 0;
}

}  // namespace

void AddSimCommand(CLI::App* app) {
  auto args = std::make_shared<Args>();
  auto* cmd = app->add_subcommand(
      "sim", "simulate a complete turntable session as a .tcap capture with a truth file");
  cmd->add_option("--protocol", args->protocol, "mip | gx2 | xbus | xbus-legacy")->required();
  cmd->add_option("--model", args->models,
                  "accelerometer and/or magnetometer model (accel12|accel13, mag13|mag22); "
                  "default accel13 and mag13")
      ->capture_default_str();
  cmd->add_option("--poses", args->poses_file,
                  "pose plan: JSON or CSV of phi, gamma, psi in degrees (default: 26 cube "
                  "directions + 10 intermediate)");
  cmd->add_option("--seed", args->seed, "random seed (same seed: byte-identical output)")
      ->capture_default_str();
  cmd->add_option("--dwell", args->dwell_s, "seconds at rest per pose after settling")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--rate", args->rate_hz,
                  "output rate in Hz (default: mip 500, gx2/xbus/xbus-legacy 100)");
  cmd->add_option("--baud", args->baud, "link baud rate (default: mip 921600, others 115200)");
  cmd->add_option("--class", args->sensor_class, "industrial | consumer (SENSORS.md)")
      ->check(CLI::IsMember({"industrial", "consumer"}))
      ->capture_default_str();
  cmd->add_option("--truth-out", args->truth_out, "JSON file of the true parameters");
  cmd->add_option("-o,--output", args->output, "the capture to write (.tcap)");
  cmd->add_option("--acc-noise", args->acc_noise,
                  "accelerometer white noise density, m/s^2/sqrt(Hz) (default: the class's)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--acc-bias-instability", args->acc_bias_instability,
                  "accelerometer bias instability (Gauss-Markov 1 sigma), m/s^2")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--gyr-noise", args->gyr_noise, "gyro white noise density, rad/s/sqrt(Hz)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--mag-noise", args->mag_noise, "magnetometer white noise, Gauss RMS per sample")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--mag-bias-instability", args->mag_bias_instability,
                  "magnetometer bias instability (Gauss-Markov 1 sigma), Gauss")
      ->check(CLI::NonNegativeNumber);
  cmd->add_flag("--no-quantisation", args->no_quantisation, "floats without ADC steps");
  cmd->add_flag("--faults", args->faults,
                "inject faults: bit flips (~1 frame in 500), dropped bytes (~1 in 700), one "
                "saturated sample, pose 1 announced 0.5 s before the table settled");
  cmd->add_option("--live", args->live,
                  "also stream the device's bytes to this pty at real time (pose events on "
                  "standard output)");
  cmd->add_option("--live-speed", args->live_speed, "time scale of --live (2 = twice as fast)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->callback([args] {
    if (args->output.empty() && args->live.empty()) {
      throw CLI::ValidationError("sim", "give -o FILE.tcap and/or --live PATH");
    }
    throw CLI::RuntimeError(Run(*args));
  });
}

}  // namespace turncal::tools
