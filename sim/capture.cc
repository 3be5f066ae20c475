#include "sim/capture.h"

#include "sim/device.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>
#include <span>
#include <utility>

#include "core/frames/reference.h"
#include "core/frames/units.h"
#include "core/modeling/measurement_model.h"
#include "drivers/gx2/gx2_encoder.h"
#include "drivers/mip/mip_encoder.h"
#include "drivers/xbus/xbus_encoder.h"
#include "protocol/pose_json.h"

namespace turncal::sim {

namespace {

using Bytes = std::vector<std::uint8_t>;

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

// temp, calibrated, counter: what the device emulator reports (sim/device.h).
constexpr drivers::XbusLegacyLayout kLegacyLayout = kSimXbusLegacyLayout;

}  // namespace

double SimDefaultRateHz(drivers::Protocol protocol) { return Defaults(protocol).rate_hz; }

std::vector<std::uint8_t> EncodeSimSample(drivers::Protocol p, const Sample& s) {
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

namespace {

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

// The model `name`, which must measure `kind`; nullptr with a message otherwise.
std::unique_ptr<MeasurementModel> CheckedModel(const std::string& name, SensorKind kind,
                                               const Mat3<double>& mount, std::string* error) {
  ModelContext context;
  context.mounting = mount;
  auto model = MakeModel(name, context, error);
  if (!model) return nullptr;
  if (name == "mag-physical") {
    *error = "mag-physical is for the observability demonstration only";
    return nullptr;
  }
  if (model->sensor() != kind) {
    *error = fmt::format("'{}' is not {} model", name,
                         kind == SensorKind::kAccelerometer ? "an accelerometer"
                         : kind == SensorKind::kGyroscope   ? "a gyroscope"
                                                            : "a magnetometer");
    return nullptr;
  }
  return model;
}

// The session's models, checked: an accelerometer, a magnetometer and, if named, a gyroscope
// (which rate segments among the poses need).
struct SimModels {
  std::unique_ptr<MeasurementModel> accel, mag, gyro;
};

bool CheckModels(const SimCaptureOptions& options, SimModels* models, std::string* error) {
  models->accel =
      CheckedModel(options.accel_model, SensorKind::kAccelerometer, options.mount, error);
  if (!models->accel) return false;
  models->mag = CheckedModel(options.mag_model, SensorKind::kMagnetometer, options.mount, error);
  if (!models->mag) return false;
  if (!options.gyro_model.empty()) {
    models->gyro = CheckedModel(options.gyro_model, SensorKind::kGyroscope, options.mount, error);
    if (!models->gyro) return false;
  }
  for (const auto& p : options.poses) {
    if (p.is_rate() && !models->gyro) {
      *error = "rate segments need a gyroscope model (--model gyro12 or gyro21)";
      return false;
    }
  }
  return true;
}

// The link budget (SENSORS.md): rate x frame size must fit in baud / bits-per-byte.
bool CheckLinkBudget(drivers::Protocol protocol, double rate_hz, int baud, std::string* error) {
  Sample probe;
  probe.t_device_s = 1.0;
  probe.counter = 1;
  probe.acc_mps2 = probe.gyr_radps = probe.mag = Eigen::Vector3d::Zero();
  probe.temp_c = 25.0;
  const double frame_bytes = static_cast<double>(EncodeSimSample(protocol, probe).size());
  const double capacity = static_cast<double>(baud) / Defaults(protocol).bits_per_byte;
  if (frame_bytes * rate_hz > capacity) {
    *error = fmt::format(
        "{} frames of {} bytes at {} Hz need {:.0f} bytes/s, more than {} baud carries ({:.0f} "
        "bytes/s): lower --rate or raise --baud",
        drivers::ToString(protocol), frame_bytes, rate_hz, frame_bytes * rate_hz, baud, capacity);
    return false;
  }
  return true;
}

// The capture's header: one device, "simulated", and a note of how it was made.
drivers::CaptureHeader HeaderFor(const SimCaptureOptions& options, const SessionSimOptions& o,
                                 int baud) {
  const drivers::Protocol protocol = options.protocol;
  drivers::CaptureHeader header;
  drivers::CaptureDevice device{"imu", protocol, baud, std::nullopt, std::nullopt};
  if (protocol == drivers::Protocol::kXbusLegacy) {
    device.output_mode = kLegacyLayout.output_mode;
    device.output_settings = kLegacyLayout.output_settings;
  }
  header.devices.push_back(device);
  header.created = "simulated";
  header.note = fmt::format(
      "turncal sim --protocol {} --model {} --model {}{} --class {} --seed {} --rate {} --dwell {} "
      "(acc noise {} m/s^2/sqrt(Hz), acc bias instability {} m/s^2, gyr noise {} rad/s/sqrt(Hz), "
      "mag noise {} G, mag bias instability {} G, quantisation {}{})",
      drivers::ToString(protocol), options.accel_model, options.mag_model,
      options.gyro_model.empty() ? "" : " --model " + options.gyro_model, o.sensor.name, o.seed,
      o.rate_hz, o.dwell_s, o.sensor.acc_noise_density, o.sensor.acc_bias_instability,
      o.sensor.gyr_noise_density, o.sensor.mag_noise_rms, o.sensor.mag_bias_instability,
      o.sensor.acc_quantum > 0 ? "16-bit" : "none", options.faults ? ", faults" : "");
  return header;
}

// The records of a simulated capture after its header: the start-up dialogue, the device's
// bytes in bursts of burst_ms, each pose's announcement after the bytes received before it, and
// the end; with faults, bit flips and dropped bytes in the frames, one saturated sample and pose
// 1 announced early (c->faults says which).
class CaptureRecorder {
 public:
  CaptureRecorder(const SimCaptureOptions& options, SimCapture* c)
      : options_(options),
        c_(*c),
        session_(c->session),
        o_(c->session_options),
        burst_ns_(static_cast<std::int64_t>(options.burst_ms * 1e6)),
        fault_rng_(o_.seed ^ 0x5eedfa17ull) {}

  void Record() {
    RecordStartUp();
    PlanFaults();
    for (std::size_t k = 0; k < session_.samples.size(); ++k) RecordSample(k);
    const auto end_ns =
        c_.offset_ns + static_cast<std::int64_t>(std::llround(session_.duration_s * 1e9));
    FlushBurst(end_ns);
    EmitEventsUntil(end_ns);
    const std::string end_event = R"({"event":"end"})";
    Append(drivers::RecordType::kEvent, end_ns, Bytes(end_event.begin(), end_event.end()));
  }

 private:
  void Append(drivers::RecordType type, std::int64_t at, std::span<const std::uint8_t> payload) {
    c_.records.push_back(
        {type, 0, static_cast<std::uint64_t>(at), Bytes(payload.begin(), payload.end())});
  }

  // What the host sends and the device answers, 2 ms apart; the session starts after it.
  void RecordStartUp() {
    std::int64_t t_ns = 0;
    for (const auto& [sent, reply] : StartUp(options_.protocol, o_.seed, o_.rate_hz, 1000.0)) {
      Append(drivers::RecordType::kSent, t_ns, sent);
      t_ns += 2'000'000;
      Append(drivers::RecordType::kReceived, t_ns, reply);
      t_ns += 2'000'000;
    }
    c_.offset_ns = t_ns;
  }

  // Faults on request: a bit flip about every 500th frame, a dropped byte about every 700th, one
  // saturated sample, and pose 1 announced while the table is still moving into it.
  void PlanFaults() {
    if (!options_.faults) return;
    SimFaultReport& faults = c_.faults;
    faults.saturated_index = session_.samples.size() / 3;
    if (session_.events.size() > 1) {
      faults.early_pose_index = 1;
      // Not before the previous announcement, so the events stay in order.
      faults.early_s = std::min(o_.settle_s + kSimEarlyBeforeMoveEnd_s,
                                session_.events[1].t_s - session_.events[0].t_s);
    }
  }

  // How early an event is announced (the early pose's early_s; 0 for the others).
  double EarlyS(const SessionPoseEvent& e) const {
    return e.index == c_.faults.early_pose_index ? c_.faults.early_s : 0.0;
  }

  // An event's announcement time in the capture.
  std::int64_t EventNs(const SessionPoseEvent& e) const {
    return c_.offset_ns + static_cast<std::int64_t>(std::llround((e.t_s - EarlyS(e)) * 1e9));
  }

  void FlushBurst(std::int64_t at) {
    if (!burst_.empty()) {
      Append(drivers::RecordType::kReceived, at, burst_);
      burst_.clear();
    }
    burst_start_ = -1;
  }

  // The event a pose's (or rate segment's) announcement records.
  std::string EventText(const SessionPoseEvent& e) const {
    if (e.pose.is_rate()) {
      nlohmann::json j = protocol::ToJson(e.pose);
      j["event"] = "rate";
      j["index"] = e.index;
      j["dwell_s"] = o_.dwell_s;
      j["hold_s"] = e.dwell_end_s - e.t_s + 2.0;
      return j.dump();
    }
    return nlohmann::json{{"event", "pose"},
                          {"index", e.index},
                          {"phi_deg", e.pose.phi_rad * kDegPerRad},
                          {"gamma_deg", e.pose.gamma_rad * kDegPerRad},
                          {"psi_deg", e.pose.psi_rad * kDegPerRad},
                          {"hold_s", o_.dwell_s + EarlyS(e)}}
        .dump();
  }

  // The events announced by `at`, each after the bytes received before it.
  void EmitEventsUntil(std::int64_t at) {
    while (next_event_ < session_.events.size() && EventNs(session_.events[next_event_]) <= at) {
      const auto& e = session_.events[next_event_++];
      const std::int64_t te = EventNs(e);
      FlushBurst(te);
      const std::string event = EventText(e);
      Append(drivers::RecordType::kEvent, te, Bytes(event.begin(), event.end()));
    }
  }

  // Sample k's frame into the burst, after the events due before it.
  void RecordSample(std::size_t k) {
    Sample s = session_.samples[k];
    const std::int64_t at = c_.offset_ns + s.t_host_ns;
    EmitEventsUntil(at);
    if (burst_start_ >= 0 && at - burst_start_ >= burst_ns_) FlushBurst(at);
    if (burst_start_ < 0) burst_start_ = at;
    if (options_.faults && k == c_.faults.saturated_index) {
      // A saturated sample: the accelerometer clips at its range on x.
      s.acc_mps2->x() = 16 * kStandardGravity_mps2;
      s.flags |= kAccSaturated;
    }
    Bytes frame = EncodeSimSample(options_.protocol, s);
    if (options_.faults) DamageFrame(&frame);
    burst_.insert(burst_.end(), frame.begin(), frame.end());
  }

  // With faults: a flipped bit in about one frame in 500, a dropped byte in about one in 700.
  void DamageFrame(Bytes* frame) {
    if (one_in_(fault_rng_) < 2000) {
      const auto byte = static_cast<std::size_t>(one_in_(fault_rng_)) % frame->size();
      (*frame)[byte] ^= static_cast<std::uint8_t>(1u << (one_in_(fault_rng_) % 8));
      ++c_.faults.bit_flips;
    }
    if (one_in_(fault_rng_) < 1430) {
      frame->erase(
          frame->begin() +
          static_cast<long>(static_cast<std::size_t>(one_in_(fault_rng_)) % frame->size()));
      ++c_.faults.dropped_bytes;
    }
  }

  const SimCaptureOptions& options_;
  SimCapture& c_;
  const SimulatedSession& session_;
  const SessionSimOptions& o_;
  const std::int64_t burst_ns_;
  std::mt19937_64 fault_rng_;
  std::uniform_int_distribution<int> one_in_{0, 999999};
  Bytes burst_;
  std::int64_t burst_start_ = -1;
  std::size_t next_event_ = 0;
};

}  // namespace

bool BuildSimCapture(const SimCaptureOptions& options, SimCapture* out, std::string* error) {
  SimModels models;
  if (!CheckModels(options, &models, error)) return false;
  const ProtocolDefaults d = Defaults(options.protocol);
  SessionSimOptions o = options.session;
  if (!(o.rate_hz > 0)) o.rate_hz = d.rate_hz;
  if (!o.IsValid(error)) return false;
  const int baud = options.baud > 0 ? options.baud : d.baud;
  if (!CheckLinkBudget(options.protocol, o.rate_hz, baud, error)) return false;

  SimCapture& c = *out;
  c = SimCapture{};
  c.session = SimulateSession(*models.accel, *models.mag, options.poses, o, models.gyro.get());
  c.session_options = o;
  c.baud = baud;
  c.accel_model = options.accel_model;
  c.mount = options.mount;
  c.mag_model = options.mag_model;
  c.gyro_model = options.gyro_model;
  c.header = HeaderFor(options, o, baud);
  CaptureRecorder(options, &c).Record();
  return true;
}

std::vector<std::uint8_t> EncodeSimCapture(const SimCapture& capture) {
  const std::string header = drivers::EncodeCaptureHeader(capture.header);
  std::vector<std::uint8_t> bytes(header.begin(), header.end());
  for (const auto& r : capture.records) {
    drivers::AppendCaptureRecord(r.type, r.device, r.t_ns, r.payload, &bytes);
  }
  return bytes;
}

bool WriteSimCapture(const SimCapture& capture, const std::string& path, std::string* error) {
  auto writer = drivers::CaptureWriter::Create(path, capture.header, error);
  if (writer == nullptr) return false;
  for (const auto& r : capture.records) {
    if (!writer->Append(r.type, r.device, r.t_ns, r.payload, error)) return false;
  }
  return writer->Close(error);
}

}  // namespace turncal::sim
