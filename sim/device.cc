#include "sim/device.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

#include "drivers/bytes.h"
#include "drivers/mip/mip_decoder.h"
#include "drivers/mip/mip_encoder.h"
#include "drivers/mip/mip_stored.h"
#include "drivers/xbus/mtdata2.h"
#include "drivers/xbus/xbus_decoder.h"
#include "drivers/xbus/xbus_encoder.h"
#include "sim/mip_storage.h"

namespace turncal::sim {

namespace {

using Bytes = std::vector<std::uint8_t>;

// Collects the frames a decoder accepts; the emulator answers them after each push.
class FrameCollector : public drivers::DecoderSink {
 public:
  void OnFrame(const drivers::FrameView& f) override {
    frames.emplace_back(f.bytes.begin(), f.bytes.end());
  }
  void OnSample(const Sample&) override {}
  std::vector<Bytes> frames;
};

// The parts every protocol with a dialogue shares: the decoder that scans the host's bytes, and
// the counters.
class ScanningEmulator : public DeviceEmulator {
 public:
  Bytes OnHostBytes(std::span<const std::uint8_t> bytes) override {
    const std::int64_t now = NowNs();
    decoder_->CheckTimeout(now);
    decoder_->Push(bytes, now);
    UpdateCounters();
    Bytes out;
    std::vector<Bytes> frames;
    frames.swap(collector_.frames);
    for (const Bytes& f : frames) Answer(f, &out);
    return out;
  }
  const Counters& counters() const override { return counters_; }

 protected:
  void SetDecoder(std::unique_ptr<drivers::Decoder> decoder) { decoder_ = std::move(decoder); }
  // Appends the reply to one accepted frame.
  virtual void Answer(const Bytes& frame, Bytes* out) = 0;

  FrameCollector collector_;
  Counters counters_;

 private:
  void UpdateCounters() {
    const drivers::DecoderCounters& c = decoder_->counters();
    counters_.bad_frames = c.bad_checksums + c.bad_structure + c.timeouts;
    counters_.ignored_bytes = c.bytes_skipped;
  }
  std::unique_ptr<drivers::Decoder> decoder_;
};

// ---------------------------------------------------------------------------------------------
// MIP

constexpr std::uint8_t kAck = 0, kUnknownCommand = 1, kBadParameter = 3, kFailed = 4;

std::string Padded16(const std::string& s) {
  std::string out = s.substr(0, 16);
  out.resize(16, ' ');
  return out;
}

bool KnownImuDescriptor(std::uint8_t d) {
  switch (d) {
    case 0x04:
    case 0x05:
    case 0x06:
    case 0x07:
    case 0x08:
    case 0x0E:
    case 0x12:
    case 0x14:
    case 0x18:
      return true;
    default:
      return false;
  }
}

class MipEmulator final : public ScanningEmulator {
 public:
  MipEmulator(const EmulatedIdentity& id, double rate_hz)
      : id_(id), nonvolatile_(id.mip_stored), base_rate_(MipBaseRate(rate_hz)) {
    if (!id.mip_nonvolatile_path.empty()) {
      std::string e;
      if (!ReadMipNonvolatile(id.mip_nonvolatile_path, id.mip_stored, &nonvolatile_, &e)) {
        storage_error_ = e;  // a corrupt storage: the device starts with its power-up values
      }
    }
    stored_ = nonvolatile_;
    decimation_at_power_up_ =
        static_cast<std::uint16_t>(std::clamp(rate_hz > 0 ? std::round(base_rate_ / rate_hz) : 1.0,
                                              1.0, static_cast<double>(base_rate_)));
    PowerUp();
    SetDecoder(std::make_unique<drivers::MipDecoder>("emulated host", &collector_));
  }

  bool streaming() const override { return !idle_ && sensor_stream_on_; }
  drivers::Protocol protocol() const override { return drivers::Protocol::kMip; }
  // The simulator's sample carries the stored calibration the session was made with (the
  // identity's power-up values); the device outputs it with stored_ in use: each triad's raw
  // value recovered through the one and corrected through the other (bit for bit when equal).
  void ApplyStored(Sample* s) const override {
    drivers::mip::ReexpressMipOutput(id_.mip_stored, stored_, s);
  }
  std::optional<drivers::mip::StoredCalibration> mip_stored() const override { return stored_; }
  std::optional<drivers::mip::StoredCalibration> mip_nonvolatile() const override {
    return nonvolatile_;
  }
  const std::string& storage_error() const override { return storage_error_; }
  std::optional<double> requested_rate_hz() const override {
    if (!host_configured_) return std::nullopt;
    for (const auto& [desc, decimation] : format_) {
      if (desc == 0x04) return static_cast<double>(base_rate_) / decimation;
    }
    return std::nullopt;
  }

 private:
  struct Result {
    std::uint8_t code = kAck;
    std::vector<drivers::mip::Field> data;
  };

  void PowerUp() {
    idle_ = false;
    sensor_stream_on_ = true;
    filter_stream_on_ = false;
    format_ = DefaultFormat();
  }

  std::vector<std::pair<std::uint8_t, std::uint16_t>> DefaultFormat() const {
    const std::uint16_t d = decimation_at_power_up_;
    return {{0x04, d}, {0x05, d}, {0x06, d}, {0x14, d}};
  }

  void Answer(const Bytes& frame, Bytes* out) override {
    const std::uint8_t set = frame[2];
    const std::size_t end = 4u + frame[3];
    if (set >= 0x80) {  // a data packet, not a command: a device ignores it
      ++counters_.unknown_commands;
      return;
    }
    std::vector<drivers::mip::Field> reply;
    std::size_t reply_bytes = 0;
    auto flush = [&] {
      if (reply.empty()) return;
      const Bytes p = drivers::mip::Packet(set, reply);
      out->insert(out->end(), p.begin(), p.end());
      reply.clear();
      reply_bytes = 0;
    };
    // The decoder accepted the frame, so its fields tile the payload.
    for (std::size_t at = 4; at < end; at += frame[at]) {
      const std::uint8_t desc = frame[at + 1];
      const std::span<const std::uint8_t> data(frame.data() + at + 2, frame[at] - 2u);
      ++counters_.commands;
      Result r = Execute(set, desc, data);
      if (r.code == kUnknownCommand) ++counters_.unknown_commands;
      std::size_t size = 4;
      for (const auto& f : r.data) size += f.data.size() + 2;
      if (reply_bytes + size > 255) flush();
      reply.push_back({0xF1, {desc, r.code}});
      if (r.code == kAck) reply.insert(reply.end(), r.data.begin(), r.data.end());
      reply_bytes += size;
    }
    flush();
  }

  Result Execute(std::uint8_t set, std::uint8_t desc, std::span<const std::uint8_t> data) {
    if (set == 0x01) return Base(desc);
    if (set == 0x0C) return ThreeDm(desc, data);
    return {kUnknownCommand, {}};
  }

  Result Base(std::uint8_t desc) {
    switch (desc) {
      case 0x01:  // ping
        return {};
      case 0x02:  // set to idle
        idle_ = true;
        return {};
      case 0x03: {  // device info
        drivers::mip::Field f{0x81, {}};
        drivers::PutU16(&f.data, id_.mip_firmware);
        for (const std::string* s :
             {&id_.model_name, &id_.model_number, &id_.serial, &id_.lot, &id_.options}) {
          const std::string padded = Padded16(*s);
          f.data.insert(f.data.end(), padded.begin(), padded.end());
        }
        return {kAck, {std::move(f)}};
      }
      case 0x06:  // resume
        idle_ = false;
        return {};
      case 0x7E:  // device reset
        PowerUp();
        host_configured_ = false;
        stored_ = nonvolatile_;
        return {};
      default:
        return {kUnknownCommand, {}};
    }
  }

  Result ThreeDm(std::uint8_t desc, std::span<const std::uint8_t> data) {
    switch (desc) {
      case 0x06: {  // IMU base rate
        drivers::mip::Field f{0x83, {}};
        drivers::PutU16(&f.data, base_rate_);
        return {kAck, {std::move(f)}};
      }
      case 0x08:
        return ImuMessageFormat(data);
      case 0x11:
        return EnableStream(data);
      case 0x37:
        return Stored(0x9A, &drivers::mip::StoredCalibration::accel_bias, data);
      case 0x38:
        return Stored(0x9B, &drivers::mip::StoredCalibration::gyro_bias, data);
      case 0x3A:
        return Stored(0x9C, &drivers::mip::StoredCalibration::hard_iron, data);
      case 0x3B:
        return StoredMatrix(0x9D, &drivers::mip::StoredCalibration::soft_iron, data);
      case 0x33:
        return StoredMatrix(0xB3, &drivers::mip::StoredCalibration::transform, data);
      default:
        return {kUnknownCommand, {}};
    }
  }

  Result ImuMessageFormat(std::span<const std::uint8_t> data) {
    if (data.empty()) return {kBadParameter, {}};
    switch (data[0]) {
      case 1: {
        if (data.size() < 2 || data.size() != 2u + 3u * data[1]) return {kBadParameter, {}};
        std::vector<std::pair<std::uint8_t, std::uint16_t>> format;
        for (std::size_t i = 0; i < data[1]; ++i) {
          const std::uint8_t d = data[2 + 3 * i];
          const std::uint16_t decimation = drivers::LoadU16(data.data() + 3 + 3 * i);
          if (!KnownImuDescriptor(d) || decimation == 0) return {kBadParameter, {}};
          format.emplace_back(d, decimation);
        }
        format_ = std::move(format);
        host_configured_ = true;
        return {};
      }
      case 2: {
        drivers::mip::Field f{0x80, {static_cast<std::uint8_t>(format_.size())}};
        for (const auto& [d, decimation] : format_) {
          f.data.push_back(d);
          drivers::PutU16(&f.data, decimation);
        }
        return {kAck, {std::move(f)}};
      }
      case 3:
      case 4:
        return {};
      case 5:
        format_ = DefaultFormat();
        host_configured_ = false;
        return {};
      default:
        return {kBadParameter, {}};
    }
  }

  Result EnableStream(std::span<const std::uint8_t> data) {
    if (data.empty()) return {kBadParameter, {}};
    const std::uint8_t fn = data[0];
    if (fn >= 3 && fn <= 5) {
      if (fn == 5) {
        sensor_stream_on_ = true;
        filter_stream_on_ = false;
      }
      return {};
    }
    if (data.size() < 2 || (data[1] != 0x80 && data[1] != 0x82)) return {kBadParameter, {}};
    bool* on = data[1] == 0x80 ? &sensor_stream_on_ : &filter_stream_on_;
    if (fn == 1) {
      if (data.size() != 3) return {kBadParameter, {}};
      *on = data[2] != 0;
      return {};
    }
    if (fn == 2) {
      return {kAck, {{0x85, {data[1], static_cast<std::uint8_t>(*on ? 1 : 0)}}}};
    }
    return {kBadParameter, {}};
  }

  using VectorEntry = std::optional<Eigen::Vector3d> drivers::mip::StoredCalibration::*;

  // Save (function 3): the values in use become the startup values, kept in the file when the
  // device has one (a file that cannot be written: NACK 4 "failed", nothing saved).
  template <typename Entry>
  Result Save(Entry entry) {
    drivers::mip::StoredCalibration saved = nonvolatile_;
    saved.*entry = stored_.*entry;
    if (!id_.mip_nonvolatile_path.empty()) {
      std::string e;
      if (!WriteMipNonvolatile(id_.mip_nonvolatile_path, saved, &e)) {
        storage_error_ = e;
        return {kFailed, {}};
      }
    }
    nonvolatile_ = saved;
    return {};
  }

  Result Stored(std::uint8_t reply_desc, VectorEntry entry, std::span<const std::uint8_t> data) {
    std::optional<Eigen::Vector3d>* value = &(stored_.*entry);
    if (!*value) return {kUnknownCommand, {}};
    if (data.empty()) return {kBadParameter, {}};
    switch (data[0]) {
      case 1:
        if (data.size() != 1 + 12) return {kBadParameter, {}};
        for (int i = 0; i < 3; ++i) (**value)[i] = drivers::LoadF32(data.data() + 1 + 4 * i);
        return {};
      case 2: {
        drivers::mip::Field f{reply_desc, {}};
        for (int i = 0; i < 3; ++i) drivers::PutF32(&f.data, static_cast<float>((**value)[i]));
        return {kAck, {std::move(f)}};
      }
      case 3:
        return Save(entry);
      case 4:
        *value = nonvolatile_.*entry;
        return {};
      case 5:
        **value = Eigen::Vector3d::Zero();
        return {};
      default:
        return {kBadParameter, {}};
    }
  }

  using MatrixEntry = std::optional<Eigen::Matrix3d> drivers::mip::StoredCalibration::*;
  Result StoredMatrix(std::uint8_t reply_desc, MatrixEntry entry,
                      std::span<const std::uint8_t> data) {
    std::optional<Eigen::Matrix3d>& m = stored_.*entry;
    if (!m) return {kUnknownCommand, {}};
    if (data.empty()) return {kBadParameter, {}};
    switch (data[0]) {
      case 1:
        if (data.size() != 1 + 36) return {kBadParameter, {}};
        for (int i = 0; i < 9; ++i) (*m)(i / 3, i % 3) = drivers::LoadF32(data.data() + 1 + 4 * i);
        return {};
      case 2: {
        drivers::mip::Field f{reply_desc, {}};
        for (int i = 0; i < 9; ++i)
          drivers::PutF32(&f.data, static_cast<float>((*m)(i / 3, i % 3)));
        return {kAck, {std::move(f)}};
      }
      case 3:
        return Save(entry);
      case 4:
        m = nonvolatile_.*entry;
        return {};
      case 5:
        *m = Eigen::Matrix3d::Identity();
        return {};
      default:
        return {kBadParameter, {}};
    }
  }

  EmulatedIdentity id_;
  drivers::mip::StoredCalibration nonvolatile_;  // the startup values (save, load, power-up)
  drivers::mip::StoredCalibration stored_;       // the values in use
  std::string storage_error_;
  std::uint16_t base_rate_;
  std::uint16_t decimation_at_power_up_ = 1;
  bool idle_ = false;
  bool sensor_stream_on_ = true;
  bool filter_stream_on_ = false;
  bool host_configured_ = false;
  std::vector<std::pair<std::uint8_t, std::uint16_t>> format_;
};

// ---------------------------------------------------------------------------------------------
// Xbus

constexpr std::uint8_t kInvalidMessage = 0x04, kInvalidParameter = 0x21;

class XbusEmulator final : public ScanningEmulator {
 public:
  XbusEmulator(const EmulatedIdentity& id, double rate_hz, bool legacy)
      : id_(id), rate_hz_(rate_hz), legacy_(legacy) {
    SetDecoder(std::make_unique<drivers::XbusDecoder>("emulated host", &collector_));
  }

  bool streaming() const override { return !config_; }
  drivers::Protocol protocol() const override {
    return legacy_ ? drivers::Protocol::kXbusLegacy : drivers::Protocol::kXbus;
  }
  std::optional<double> requested_rate_hz() const override {
    if (legacy_) return std::nullopt;
    for (const auto& [xdi, rate] : output_) {
      if ((xdi & 0xFFF0) == drivers::xbus::kAcceleration)
        return rate == 0xFFFF ? rate_hz_ : static_cast<double>(rate);
    }
    return std::nullopt;
  }

 private:
  void Answer(const Bytes& frame, Bytes* out) override {
    namespace xbus = drivers::xbus;
    const std::uint8_t mid = frame[2];
    const auto payload = drivers::XbusDecoder::Payload(frame);
    ++counters_.commands;
    auto reply = [&](std::uint8_t reply_mid, std::span<const std::uint8_t> data = {}) {
      const Bytes m = xbus::Message(reply_mid, data);
      out->insert(out->end(), m.begin(), m.end());
    };
    auto error = [&](std::uint8_t code) {
      const std::uint8_t c[1] = {code};
      reply(xbus::kError, c);
    };
    const auto ack = static_cast<std::uint8_t>(mid + 1);
    switch (mid) {
      case xbus::kGoToConfig:
        config_ = true;
        return reply(ack);
      case xbus::kGoToMeasurement:
        config_ = false;
        return reply(ack);
      case xbus::kWakeUpAck:
        config_ = true;
        return;
      case xbus::kReset:
        config_ = false;
        output_.clear();
        return reply(ack);
      case xbus::kReqDid: {
        Bytes d;
        drivers::PutU32(&d, id_.xbus_device_id);
        return reply(xbus::kDeviceId, d);
      }
      case xbus::kReqProductCode: {
        const std::string& code = id_.xbus_product_code;
        return reply(xbus::kProductCode, Bytes(code.begin(), code.end()));
      }
      case xbus::kReqFwRev:
        return reply(ack, id_.xbus_firmware);
      default:
        break;
    }
    if (!legacy_ && mid == xbus::kSetOutputConfiguration) {
      if (payload.empty()) {  // the request form: the current configuration
        Bytes d;
        for (const auto& [xdi, rate] : output_) {
          drivers::PutU16(&d, xdi);
          drivers::PutU16(&d, rate);
        }
        return reply(ack, d);
      }
      if (payload.size() % 4 != 0 || payload.size() > 32 * 4) return error(kInvalidParameter);
      output_.clear();
      for (std::size_t at = 0; at < payload.size(); at += 4) {
        output_.emplace_back(drivers::LoadU16(payload.data() + at),
                             drivers::LoadU16(payload.data() + at + 2));
      }
      return reply(ack, payload);
    }
    if (legacy_ && mid == xbus::kReqOutputMode) {
      Bytes d;
      drivers::PutU16(&d, id_.xbus_legacy_layout.output_mode);
      if (payload.empty()) return reply(ack, d);
      return payload.size() == d.size() && std::equal(d.begin(), d.end(), payload.begin())
                 ? reply(ack)
                 : error(kInvalidParameter);
    }
    if (legacy_ && mid == xbus::kReqOutputSettings) {
      Bytes d;
      drivers::PutU32(&d, id_.xbus_legacy_layout.output_settings);
      if (payload.empty()) return reply(ack, d);
      return payload.size() == d.size() && std::equal(d.begin(), d.end(), payload.begin())
                 ? reply(ack)
                 : error(kInvalidParameter);
    }
    ++counters_.unknown_commands;
    error(kInvalidMessage);
  }

  EmulatedIdentity id_;
  double rate_hz_;
  bool legacy_;
  bool config_ = false;
  std::vector<std::pair<std::uint16_t, std::uint16_t>> output_;
};

// ---------------------------------------------------------------------------------------------
// gx2: no dialogue

class Gx2Emulator final : public DeviceEmulator {
 public:
  Bytes OnHostBytes(std::span<const std::uint8_t> bytes) override {
    counters_.ignored_bytes += bytes.size();
    return {};
  }
  bool streaming() const override { return true; }
  const Counters& counters() const override { return counters_; }
  drivers::Protocol protocol() const override { return drivers::Protocol::kGx2; }

 private:
  Counters counters_;
};

}  // namespace

std::uint16_t MipBaseRate(double rate_hz) {
  if (!(rate_hz > 0) || !std::isfinite(rate_hz)) return 1000;
  // The tolerance keeps 1000/3 Hz (and the like) at 1000 Hz despite rounding.
  const double k = std::max(1.0, std::ceil(1000.0 / rate_hz - 1e-6));
  return static_cast<std::uint16_t>(std::clamp(std::round(k * rate_hz), 1.0, 65535.0));
}

DeviceEmulator::DeviceEmulator()
    : now_ns_([] {
        return std::chrono::duration_cast<std::chrono::nanoseconds>(
                   std::chrono::steady_clock::now().time_since_epoch())
            .count();
      }) {}

DeviceEmulator::~DeviceEmulator() = default;

std::unique_ptr<DeviceEmulator> DeviceEmulator::Make(drivers::Protocol protocol,
                                                     const EmulatedIdentity& id, double rate_hz) {
  switch (protocol) {
    case drivers::Protocol::kMip:
      return std::make_unique<MipEmulator>(id, rate_hz);
    case drivers::Protocol::kXbus:
      return std::make_unique<XbusEmulator>(id, rate_hz, false);
    case drivers::Protocol::kXbusLegacy:
      return std::make_unique<XbusEmulator>(id, rate_hz, true);
    case drivers::Protocol::kGx2:
      return std::make_unique<Gx2Emulator>();
  }
  return nullptr;
}

}  // namespace turncal::sim
