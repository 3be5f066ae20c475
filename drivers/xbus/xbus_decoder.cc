#include "drivers/xbus/xbus_decoder.h"

#include <fmt/format.h>

#include "drivers/bytes.h"
#include "drivers/checksum.h"

namespace turncal::drivers {

namespace {

constexpr std::uint8_t kPreamble = 0xFA;
constexpr std::uint8_t kMtData = 0x32, kMtData2 = 0x36;

}  // namespace

std::optional<std::size_t> XbusLegacyLayout::PayloadSize(std::string* error) const {
  constexpr std::uint16_t kKnown = 0x0001 | 0x0002 | 0x0004 | 0x0010 | 0x0020 | 0x0800;
  if (output_mode & ~kKnown) {
    if (error) {
      *error = fmt::format(
          "OutputMode 0x{:04X} has sections this decoder does not read "
          "(auxiliary 0x0008, raw 0x4000, ...)",
          output_mode);
    }
    return std::nullopt;
  }
  const std::size_t value = static_cast<std::size_t>(xbus::ValueSize((output_settings >> 8) & 3));
  std::size_t size = 0;
  if (output_mode & 0x0001) size += value;
  if (output_mode & 0x0002) {
    for (int bit = 4; bit <= 6; ++bit)
      if (!(output_settings & (1u << bit))) size += 3 * value;
  }
  if (output_mode & 0x0004) {
    const unsigned orientation = (output_settings >> 2) & 3;
    if (orientation == 3) {
      if (error) *error = "OutputSettings orientation bits 3-2 = 11 is not a valid mode";
      return std::nullopt;
    }
    size += (orientation == 0 ? 4 : orientation == 1 ? 3 : 9) * value;
  }
  if (output_mode & 0x0010) size += 3 * value;
  if (output_mode & 0x0020) size += 3 * value;
  if (output_mode & 0x0800) size += 1;
  if ((output_settings & 3) == 1) size += 2;
  return size;
}

XbusDecoder::XbusDecoder(std::string device, DecoderSink* sink,
                         std::optional<XbusLegacyLayout> legacy, std::int64_t timeout_ns,
                         std::optional<std::uint8_t> bus_id)
    : ScanningDecoder(kXbusMaxFrame, timeout_ns, sink),
      device_(std::move(device)),
      legacy_(legacy),
      bus_id_(bus_id) {
  if (legacy_) legacy_size_ = legacy_->PayloadSize(nullptr).value_or(0);
}

std::span<const std::uint8_t> XbusDecoder::Payload(std::span<const std::uint8_t> frame) {
  const std::size_t header = frame[3] == 0xFF ? 6 : 4;
  return frame.subspan(header, frame.size() - header - 1);
}

Examination XbusDecoder::Examine(const std::uint8_t* p, std::size_t n) {
  if (p[0] != kPreamble) {
    const void* next = std::memchr(p + 1, kPreamble, n - 1);
    return {Examination::kGarbage,
            next ? static_cast<std::size_t>(static_cast<const std::uint8_t*>(next) - p) : n};
  }
  if (n < 2) return {};
  if (bus_id_ && p[1] != *bus_id_) return {Examination::kGarbage, 1};
  if (n < 4) return {};
  std::size_t header = 4, len = p[3];
  if (len == 0xFF) {
    if (n < 6) return {};
    header = 6;
    len = LoadU16(p + 4);
  }
  const std::size_t total = header + len + 1;
  if (total > kXbusMaxFrame) return {Examination::kMalformed, 1};
  if (n < total) return {};
  if ((ByteSum(p + 1, total - 1) & 0xFF) != 0) return {Examination::kBadChecksum, 1};
  // The 8-bit checksum passes for 1 in 256 corrupted candidates. A candidate whose length was
  // corrupted reaches into the next message; when a message of the same bus ID starts inside
  // this candidate and is itself valid, the candidate is the corrupted one (otherwise accepting it
  // would swallow that intact message).
  for (std::size_t q = 1; q + 1 < total; ++q) {
    const void* next = std::memchr(p + q, kPreamble, total - 1 - q);
    if (next == nullptr) break;
    q = static_cast<std::size_t>(static_cast<const std::uint8_t*>(next) - p);
    if (p[q + 1] != p[1]) continue;
    const std::size_t m = n - q;
    if (m < 4) return {};
    std::size_t other_header = 4, other_len = p[q + 3];
    if (other_len == 0xFF) {
      if (m < 6) return {};
      other_header = 6;
      other_len = LoadU16(p + q + 4);
    }
    const std::size_t other_total = other_header + other_len + 1;
    if (other_total > kXbusMaxFrame || q + other_total <= total) continue;  // not competing
    if (m < other_total) return {};  // wait for it (bounded by the timeout)
    if ((ByteSum(p + q + 1, other_total - 1) & 0xFF) == 0) return {Examination::kMalformed, 1};
  }
  return {Examination::kFrame, total};
}

void XbusDecoder::CountGap(std::uint16_t counter) {
  // Steps forward from a to b (1: b follows a), or 0 when b is not ahead of a.
  const auto ahead = [](std::uint16_t a, std::uint16_t b) -> std::uint32_t {
    const auto d = static_cast<std::uint16_t>(b - a);
    return d != 0 && d < 0x8000 ? d : 0u;
  };
  // A counter that breaks the sequence is believed when the next one continues from it. When the
  // next continues the old sequence instead (closer to it), the jump was a corrupted counter (two
  // bit errors the 8-bit checksum missed) and is not counted as lost samples. A jump in the last
  // message of a stream stays unconfirmed (not counted).
  if (jumped_) {
    const std::uint32_t from_last = ahead(*last_counter_, counter);
    const std::uint32_t from_jump = ahead(*jumped_, counter);
    if (from_last != 0 && (from_jump == 0 || from_last < from_jump)) {
      // The corrupted message stood for one of the samples in between.
      counters_.lost_samples += from_last > 2 ? from_last - 2 : 0u;
      last_counter_ = counter;
      jumped_.reset();
      return;
    }
    const std::uint32_t gap = ahead(*last_counter_, *jumped_);
    if (gap > 1) counters_.lost_samples += gap - 1;
    last_counter_ = jumped_;
    jumped_.reset();
  }
  if (last_counter_ && ahead(*last_counter_, counter) != 1) {
    jumped_ = counter;
    return;
  }
  last_counter_ = counter;
}

bool XbusDecoder::AcceptMtData2(std::span<const std::uint8_t> payload, Sample* s) {
  bool malformed = false;
  const bool filled = xbus::ForEachItem(payload, [&](const xbus::Item& item) {
    double v[3];
    switch (item.type()) {
      case xbus::kAcceleration:
      case xbus::kRateOfTurn:
      case xbus::kMagneticField: {
        if (item.data.size() != 3u * static_cast<std::size_t>(xbus::ValueSize(item.format()))) {
          malformed = true;
          return;
        }
        xbus::DecodeValues(item, v, 3);
        const Eigen::Vector3d vec(v[0], v[1], v[2]);
        if (item.type() == xbus::kAcceleration) s->acc_mps2 = vec;
        if (item.type() == xbus::kRateOfTurn) s->gyr_radps = vec;
        if (item.type() == xbus::kMagneticField) s->mag = vec;
        s->frame = xbus::FrameOf(item.xdi);
        break;
      }
      case xbus::kTemperature:
        if (xbus::DecodeValues(item, v, 1) != 1) {
          malformed = true;
          return;
        }
        s->temp_c = v[0];
        break;
      case xbus::kPacketCounter:
        if (item.data.size() != 2) {
          malformed = true;
          return;
        }
        s->counter = LoadU16(item.data.data());
        break;
      case xbus::kSampleTimeFine:
        if (item.data.size() != 4) {
          malformed = true;
          return;
        }
        s->t_device_s = LoadU32(item.data.data()) * 1e-4;
        break;
      case xbus::kStatusWord: {
        if (item.data.size() != 4) {
          malformed = true;
          return;
        }
        const std::uint32_t w = LoadU32(item.data.data());
        if (w & (7u << 8)) s->flags |= kAccSaturated;
        if (w & (7u << 11)) s->flags |= kGyrSaturated;
        if (w & (7u << 14)) s->flags |= kMagSaturated;
        if (w & (1u << 19)) s->flags |= kClipping;
        break;
      }
      default:
        if (xbus::ItemName(item.type()) == nullptr) ++counters_.unknown_fields;
        break;
    }
  });
  return filled && !malformed;
}

bool XbusDecoder::AcceptLegacy(std::span<const std::uint8_t> payload, Sample* s) {
  if (!legacy_ || legacy_size_ == 0 || payload.size() != legacy_size_) return false;
  const std::uint16_t mode = legacy_->output_mode;
  const std::uint32_t settings = legacy_->output_settings;
  const int format = static_cast<int>((settings >> 8) & 3);
  const std::size_t value = static_cast<std::size_t>(xbus::ValueSize(format));
  const std::uint8_t* p = payload.data();
  auto vec = [&]() {
    Eigen::Vector3d v(xbus::DecodeValue(p, format), xbus::DecodeValue(p + value, format),
                      xbus::DecodeValue(p + 2 * value, format));
    p += 3 * value;
    return v;
  };
  if (mode & 0x0001) {
    s->temp_c = xbus::DecodeValue(p, format);
    p += value;
  }
  if (mode & 0x0002) {
    if (!(settings & (1u << 4))) s->acc_mps2 = vec();
    if (!(settings & (1u << 5))) s->gyr_radps = vec();
    if (!(settings & (1u << 6))) s->mag = vec();
  }
  if (mode & 0x0004) {
    const unsigned orientation = (settings >> 2) & 3;
    p += (orientation == 0 ? 4 : orientation == 1 ? 3 : 9) * value;
  }
  if (mode & 0x0010) p += 3 * value;
  if (mode & 0x0020) p += 3 * value;
  if (mode & 0x0800) ++p;
  if ((settings & 3) == 1) s->counter = LoadU16(p);
  return true;
}

bool XbusDecoder::Accept(std::span<const std::uint8_t> frame, std::int64_t t_host_ns) {
  const std::uint8_t mid = frame[2];
  FrameView view{protocol(), frame, t_host_ns, mid, false};
  if (mid != kMtData2 && mid != kMtData) {
    sink_->OnFrame(view);
    return true;
  }
  Sample s;
  const auto payload = Payload(frame);
  if (!(mid == kMtData2 ? AcceptMtData2(payload, &s) : AcceptLegacy(payload, &s))) return false;
  if (s.counter) CountGap(static_cast<std::uint16_t>(*s.counter));
  view.carries_sample = s.acc_mps2 || s.gyr_radps || s.mag;
  sink_->OnFrame(view);
  if (view.carries_sample) {
    s.device = device_;
    s.t_host_ns = t_host_ns;
    ++counters_.samples;
    sink_->OnSample(s);
  }
  return true;
}

}  // namespace turncal::drivers
