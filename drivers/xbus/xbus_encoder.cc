#include "drivers/xbus/xbus_encoder.h"

#include <cassert>
#include <cmath>

#include "drivers/bytes.h"
#include "drivers/checksum.h"

namespace turncal::drivers::xbus {

std::vector<std::uint8_t> Message(std::uint8_t mid, std::span<const std::uint8_t> data,
                                  std::uint8_t bid) {
  std::vector<std::uint8_t> out = {0xFA, bid, mid};
  if (data.size() < 255) {
    out.push_back(static_cast<std::uint8_t>(data.size()));
  } else {
    out.push_back(0xFF);
    PutU16(&out, static_cast<std::uint16_t>(data.size()));
  }
  out.insert(out.end(), data.begin(), data.end());
  out.push_back(XbusChecksum(std::span<const std::uint8_t>(out).subspan(1)));
  return out;
}

const char* ErrorMeaning(std::uint8_t code) {
  switch (code) {
    case 0x03:
      return "invalid period";
    case 0x04:
      return "invalid message";
    case 0x1E:
      return "timer overflow";
    case 0x20:
      return "invalid baud rate";
    case 0x21:
      return "invalid parameter";
    case 0x28:
      return "device error";
    case 0x29:
      return "data overflow: more output than the baud rate carries";
    case 0x2A:
      return "buffer overflow";
    default:
      return "unknown error code";
  }
}

std::vector<std::uint8_t> SetOutputConfiguration(
    std::span<const std::pair<std::uint16_t, std::uint16_t>> outputs) {
  assert(outputs.size() <= 32);
  std::vector<std::uint8_t> data;
  for (const auto& [xdi, rate] : outputs) {
    PutU16(&data, xdi);
    PutU16(&data, rate);
  }
  return Message(kSetOutputConfiguration, data);
}

void AppendItem(std::uint16_t xdi, std::span<const std::uint8_t> data,
                std::vector<std::uint8_t>* out) {
  PutU16(out, xdi);
  out->push_back(static_cast<std::uint8_t>(data.size()));
  out->insert(out->end(), data.begin(), data.end());
}

void AppendValues(std::uint16_t xdi, std::span<const double> values,
                  std::vector<std::uint8_t>* out) {
  std::vector<std::uint8_t> data;
  for (double v : values) {
    switch (xdi & 3) {
      case 0:
        PutF32(&data, static_cast<float>(v));
        break;
      case 1:
        PutU32(&data,
               static_cast<std::uint32_t>(static_cast<std::int32_t>(std::llround(v * 1048576.0))));
        break;
      case 2: {
        const auto fixed = static_cast<std::int64_t>(std::llround(v * 4294967296.0));
        PutU32(&data, static_cast<std::uint32_t>(fixed & 0xFFFFFFFF));
        PutU16(&data, static_cast<std::uint16_t>(static_cast<std::int16_t>(fixed >> 32)));
        break;
      }
      default:
        PutF64(&data, v);
        break;
    }
  }
  AppendItem(xdi, data, out);
}

namespace {

std::uint16_t FrameBits(VectorFrame frame) {
  switch (frame) {
    case VectorFrame::kNed:
      return 0x4;
    case VectorFrame::kNwu:
      return 0x8;
    default:
      return 0x0;
  }
}

}  // namespace

std::vector<std::uint8_t> MtData2(const Sample& s, const MtData2Encoding& e) {
  std::vector<std::uint8_t> payload;
  const auto format = static_cast<std::uint16_t>(e.format & 3);
  const std::uint16_t vector_bits = static_cast<std::uint16_t>(format | FrameBits(e.frame));
  if (s.counter) {
    std::vector<std::uint8_t> d;
    PutU16(&d, static_cast<std::uint16_t>(*s.counter));
    AppendItem(kPacketCounter, d, &payload);
  }
  if (s.t_device_s) {
    std::vector<std::uint8_t> d;
    PutU32(&d, static_cast<std::uint32_t>(std::llround(*s.t_device_s * 1e4)));
    AppendItem(kSampleTimeFine, d, &payload);
  }
  if (s.temp_c) {
    const double t[1] = {*s.temp_c};
    AppendValues(kTemperature | format, t, &payload);
  }
  auto vec = [&](std::uint16_t type, const Eigen::Vector3d& v) {
    const double values[3] = {v.x(), v.y(), v.z()};
    AppendValues(static_cast<std::uint16_t>(type | vector_bits), values, &payload);
  };
  if (s.acc_mps2) vec(kAcceleration, *s.acc_mps2);
  if (s.gyr_radps) vec(kRateOfTurn, *s.gyr_radps);
  if (s.mag) vec(kMagneticField, *s.mag);
  std::uint32_t status = 0;
  if (s.flags & kAccSaturated) status |= 7u << 8;
  if (s.flags & kGyrSaturated) status |= 7u << 11;
  if (s.flags & kMagSaturated) status |= 7u << 14;
  if (s.flags & (kAccSaturated | kGyrSaturated | kMagSaturated | kClipping)) status |= 1u << 19;
  if (status) {
    std::vector<std::uint8_t> d;
    PutU32(&d, status);
    AppendItem(kStatusWord, d, &payload);
  }
  return Message(kMtData2, payload);
}

std::vector<std::uint8_t> MtData(const Sample& s, const XbusLegacyLayout& layout) {
  const std::uint16_t mode = layout.output_mode;
  const std::uint32_t settings = layout.output_settings;
  const auto xdi = static_cast<std::uint16_t>((settings >> 8) & 3);  // format bits only
  std::vector<std::uint8_t> items;  // built as MTData2 items, then stripped of their headers
  auto values = [&](std::initializer_list<double> v) {
    std::vector<std::uint8_t> item;
    AppendValues(xdi, std::vector<double>(v), &item);
    items.insert(items.end(), item.begin() + 3, item.end());
  };
  auto vec = [&](const std::optional<Eigen::Vector3d>& v) {
    const Eigen::Vector3d x = v.value_or(Eigen::Vector3d::Zero());
    values({x.x(), x.y(), x.z()});
  };
  if (mode & 0x0001) values({s.temp_c.value_or(0.0)});
  if (mode & 0x0002) {
    if (!(settings & (1u << 4))) vec(s.acc_mps2);
    if (!(settings & (1u << 5))) vec(s.gyr_radps);
    if (!(settings & (1u << 6))) vec(s.mag);
  }
  if (mode & 0x0004) {
    const unsigned orientation = (settings >> 2) & 3;
    for (int i = 0; i < (orientation == 0 ? 4 : orientation == 1 ? 3 : 9); ++i) values({0.0});
  }
  if (mode & 0x0010) values({0.0, 0.0, 0.0});
  if (mode & 0x0020) values({0.0, 0.0, 0.0});
  if (mode & 0x0800) items.push_back(0);
  if ((settings & 3) == 1) PutU16(&items, static_cast<std::uint16_t>(s.counter.value_or(0)));
  return Message(kMtData, items);
}

}  // namespace turncal::drivers::xbus
