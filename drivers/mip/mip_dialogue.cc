#include "drivers/mip/mip_dialogue.h"

#include <fmt/format.h>

#include <cmath>

#include "drivers/bytes.h"
#include "drivers/mip/mip_decoder.h"
#include "drivers/mip/mip_encoder.h"

namespace turncal::drivers::mip {

const char* NackMeaning(std::uint8_t code) {
  switch (code) {
    case 0:
      return "ACK";
    case 1:
      return "unknown command";
    case 2:
      return "bad checksum";
    case 3:
      return "bad parameter";
    case 4:
      return "failed";
    case 5:
      return "timeout";
    default:
      return "unknown reply code";
  }
}

Dialogue::Dialogue(ByteLink* link, ExchangeOptions options) : link_(link), options_(options) {}

std::optional<std::vector<std::pair<std::uint8_t, std::vector<std::uint8_t>>>> Dialogue::Command(
    const std::vector<std::uint8_t>& request, const std::string& what, std::string* error,
    std::uint8_t* nack_code) {
  const std::uint8_t set = request[2];
  const std::uint8_t descriptor = request[5];
  auto accept = [&](std::span<const std::uint8_t> f) {
    return f.size() >= 10 && f[2] == set && f[4] >= 4 && f[5] == 0xF1 && f[6] == descriptor;
  };
  auto make = [](DecoderSink* sink) { return std::make_unique<MipDecoder>("dialogue", sink); };
  const ExchangeResult r = Exchange(link_, request, make, accept, options_, what);
  if (!r.ok) {
    if (error) *error = r.error;
    return std::nullopt;
  }
  const std::uint8_t code = r.reply[7];
  if (nack_code) *nack_code = code;
  if (code != 0) {
    if (error)
      *error = fmt::format("{}: the device answered NACK {} ({})", what, code, NackMeaning(code));
    return std::nullopt;
  }
  std::vector<std::pair<std::uint8_t, std::vector<std::uint8_t>>> fields;
  const std::size_t end = 4u + r.reply[3];
  for (std::size_t at = 4 + r.reply[4]; at < end; at += r.reply[at]) {
    fields.emplace_back(
        r.reply[at + 1],
        std::vector<std::uint8_t>(r.reply.begin() + static_cast<long>(at) + 2,
                                  r.reply.begin() + static_cast<long>(at) + r.reply[at]));
  }
  return fields;
}

bool Dialogue::SetToIdle(std::string* error) {
  return Command(mip::SetToIdle(), "set to idle", error).has_value();
}

bool Dialogue::Resume(std::string* error) {
  return Command(mip::Resume(), "resume", error).has_value();
}

std::optional<DeviceInfo> Dialogue::GetDeviceInfo(std::string* error) {
  const auto fields = Command(mip::GetDeviceInfo(), "get device info", error);
  if (!fields) return std::nullopt;
  for (const auto& [desc, data] : *fields) {
    if (desc != 0x81 || data.size() < 2 + 5 * 16) continue;
    DeviceInfo info;
    info.firmware = LoadU16(data.data());
    std::string* strings[5] = {&info.model_name, &info.model_number, &info.serial, &info.lot,
                               &info.options};
    for (int i = 0; i < 5; ++i) {
      std::string s(reinterpret_cast<const char*>(data.data()) + 2 + 16 * i, 16);
      s.erase(s.find_last_not_of(std::string(" \0", 2)) + 1);
      s.erase(0, s.find_first_not_of(' '));
      *strings[i] = s;
    }
    return info;
  }
  if (error) *error = "get device info: the reply has no device information field (0x81)";
  return std::nullopt;
}

std::optional<std::uint16_t> Dialogue::GetImuBaseRate(std::string* error) {
  const auto fields = Command(mip::GetImuBaseRate(), "get IMU base rate", error);
  if (!fields) return std::nullopt;
  for (const auto& [desc, data] : *fields) {
    if (desc == 0x83 && data.size() >= 2) return LoadU16(data.data());
  }
  if (error) *error = "get IMU base rate: the reply has no base rate field (0x83)";
  return std::nullopt;
}

bool Dialogue::SetImuMessageFormat(
    std::span<const std::pair<std::uint8_t, std::uint16_t>> descriptors, std::string* error) {
  return Command(mip::ImuMessageFormat(descriptors), "set IMU message format", error).has_value();
}

bool Dialogue::EnableStream(std::uint8_t data_set, bool on, std::string* error) {
  return Command(mip::EnableStream(data_set, on), "enable stream", error).has_value();
}

const char* StoredQuantityName(std::uint8_t descriptor) {
  switch (descriptor) {
    case 0x37:
      return "accel bias";
    case 0x38:
      return "gyro bias";
    case 0x3A:
      return "hard-iron offset";
    case 0x3B:
      return "soft-iron matrix";
    case 0x33:
      return "sensor-to-vehicle transform";
    default:
      return "stored value";
  }
}

std::optional<StoredCalibration> Dialogue::ReadStoredCalibration(std::string* error) {
  StoredCalibration stored;
  for (const std::uint8_t descriptor : {0x37, 0x38, 0x3A, 0x3B, 0x33}) {
    const std::string what = fmt::format("read stored {}", StoredQuantityName(descriptor));
    const struct {
      std::uint8_t descriptor;
      const char* what;
    } r{descriptor, what.c_str()};
    std::uint8_t code = 0;
    std::string step_error;
    const auto fields = Command(mip::ReadStored(r.descriptor), r.what, &step_error, &code);
    if (!fields) {
      if (code == 1) continue;  // the device does not have this setting
      if (error) *error = step_error;
      return std::nullopt;
    }
    if (fields->empty()) {
      if (error) *error = std::string(r.what) + ": the reply carries no data";
      return std::nullopt;
    }
    const auto& data = fields->front().second;
    auto f = [&](int i) { return static_cast<double>(LoadF32(data.data() + 4 * i)); };
    if (r.descriptor == 0x3B || r.descriptor == 0x33) {
      if (data.size() < 36) {
        if (error) *error = std::string(r.what) + ": 9 floats expected";
        return std::nullopt;
      }
      Eigen::Matrix3d m;
      for (int i = 0; i < 9; ++i) m(i / 3, i % 3) = f(i);
      (r.descriptor == 0x3B ? stored.soft_iron : stored.transform) = m;
    } else {
      if (data.size() < 12) {
        if (error) *error = std::string(r.what) + ": 3 floats expected";
        return std::nullopt;
      }
      const Eigen::Vector3d v(f(0), f(1), f(2));
      (r.descriptor == 0x37   ? stored.accel_bias
       : r.descriptor == 0x38 ? stored.gyro_bias
                              : stored.hard_iron) = v;
    }
  }
  return stored;
}

namespace {
const char* FunctionName(std::uint8_t function) {
  switch (function) {
    case 1:
      return "write";
    case 2:
      return "read";
    case 3:
      return "save";
    case 4:
      return "load";
    case 5:
      return "default";
    default:
      return "function";
  }
}
}  // namespace

bool Dialogue::WriteStored(std::uint8_t descriptor, std::span<const double> values,
                           std::string* error, std::uint8_t* nack_code) {
  if (nack_code) *nack_code = 0xFF;
  const std::size_t want = descriptor == 0x3B || descriptor == 0x33 ? 9 : 3;
  if (values.size() != want) {
    if (error)
      *error =
          fmt::format("write stored {}: {} values expected", StoredQuantityName(descriptor), want);
    return false;
  }
  return Command(mip::WriteStored(descriptor, values),
                 fmt::format("write stored {}", StoredQuantityName(descriptor)), error, nack_code)
      .has_value();
}

bool Dialogue::StoredFunction(std::uint8_t descriptor, std::uint8_t function, std::string* error,
                              std::uint8_t* nack_code) {
  if (nack_code) *nack_code = 0xFF;
  return Command(
             mip::StoredFunction(descriptor, function),
             fmt::format("{} stored {}", FunctionName(function), StoredQuantityName(descriptor)),
             error, nack_code)
      .has_value();
}

std::optional<Configured> Dialogue::Configure(double rate_hz, std::string* error) {
  Configured c;
  if (!SetToIdle(error)) return std::nullopt;
  auto info = GetDeviceInfo(error);
  if (!info) return std::nullopt;
  c.info = *info;
  auto base = GetImuBaseRate(error);
  if (!base) return std::nullopt;
  c.base_rate_hz = *base;
  if (!(rate_hz > 0) || rate_hz > *base) {
    if (error)
      *error = fmt::format("rate {} Hz is not in (0, {}] (the IMU base rate)", rate_hz, *base);
    return std::nullopt;
  }
  c.decimation = static_cast<std::uint16_t>(std::max(1.0, std::round(*base / rate_hz)));
  const std::pair<std::uint8_t, std::uint16_t> format[] = {
      {0x04, c.decimation}, {0x05, c.decimation}, {0x06, c.decimation}};
  if (!SetImuMessageFormat(format, error)) return std::nullopt;
  auto stored = ReadStoredCalibration(error);
  if (!stored) return std::nullopt;
  c.stored = *stored;
  if (!EnableStream(0x80, true, error) || !Resume(error)) return std::nullopt;
  return c;
}

}  // namespace turncal::drivers::mip
