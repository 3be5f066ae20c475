#include "drivers/mip/mip_decoder.h"

#include "drivers/bytes.h"
#include "drivers/checksum.h"

namespace turncal::drivers {

namespace {

constexpr std::uint8_t kSync1 = 0x75, kSync2 = 0x65;
constexpr std::uint8_t kSensorSet = 0x80;

Eigen::Vector3d Vector3(const std::uint8_t* p, double scale) {
  return Eigen::Vector3d(LoadF32(p), LoadF32(p + 4), LoadF32(p + 8)) * scale;
}

}  // namespace

MipDecoder::MipDecoder(std::string device, DecoderSink* sink, std::int64_t timeout_ns, bool early)
    : ScanningDecoder(kMipMaxFrame, timeout_ns, sink), device_(std::move(device)), early_(early) {
  pending_.device = device_;
}

Examination MipDecoder::Examine(const std::uint8_t* p, std::size_t n) {
  if (p[0] != kSync1) {
    const void* next = std::memchr(p + 1, kSync1, n - 1);
    return {Examination::kGarbage,
            next ? static_cast<std::size_t>(static_cast<const std::uint8_t*>(next) - p) : n};
  }
  if (n < 2) return {};
  if (p[1] != kSync2) return {Examination::kGarbage, 1};
  if (n < 4) return {};
  const std::size_t total = 6u + p[3];
  if (n < total) return {};
  if (MipChecksumFast(p, total - 2) != LoadU16(p + total - 2)) {
    return {Examination::kBadChecksum, 1};
  }
  return {Examination::kFrame, total};
}

bool MipDecoder::Accept(std::span<const std::uint8_t> frame, std::int64_t t_host_ns) {
  const std::uint8_t set = frame[2];
  const std::size_t len = frame[3];
  if (set == 0x00) return false;  // descriptor set 0 is invalid
  // Fields must tile the payload exactly.
  for (std::size_t at = 4; at < 4 + len;) {
    const std::size_t flen = frame[at];
    if (flen < 2 || at + flen > 4 + len) return false;
    at += flen;
  }
  FrameView view{Protocol::kMip, frame, t_host_ns, set, false};
  if (set != kSensorSet) {
    sink_->OnFrame(view);
    return true;
  }

  Sample s;
  int time_rank = 0;  // 3: 0xD5, 2: 0x0E, 1: GPS
  for (std::size_t at = 4; at < 4 + len;) {
    const std::size_t flen = frame[at];
    const std::uint8_t desc = frame[at + 1];
    const std::uint8_t* d = frame.data() + at + 2;
    const std::size_t dlen = flen - 2;
    at += flen;
    switch (desc) {
      case 0x04:
        if (dlen >= 12) s.acc_mps2 = Vector3(d, kStandardGravity_mps2);
        break;
      case 0x05:
        if (dlen >= 12) s.gyr_radps = Vector3(d, 1.0);
        break;
      case 0x06:
        if (dlen >= 12) s.mag = Vector3(d, 1.0);
        break;
      case 0xD5:
        if (dlen >= 8 && time_rank < 3) {
          s.t_device_s = static_cast<double>(LoadU64(d)) * 1e-9;
          time_rank = 3;
        }
        break;
      case 0x0E:
        if (dlen >= 4 && time_rank < 2) {
          s.t_device_s = LoadU32(d) * 16e-6;
          time_rank = 2;
        }
        break;
      case 0x12:
      case 0xD3:
        if (dlen >= 12 && time_rank < 1) {
          s.t_device_s = LoadF64(d);
          time_rank = 1;
        }
        break;
      case 0x14:
        if (dlen >= 12) s.temp_c = LoadF32(d + 8);
        break;
      case 0x18:
        if (dlen >= 2) {
          const std::uint16_t bits = LoadU16(d);
          if (bits & 0x0007) s.flags |= kAccSaturated;
          if (bits & 0x0070) s.flags |= kGyrSaturated;
          if (bits & 0x0700) s.flags |= kMagSaturated;
        }
        break;
      case 0x07:  // delta theta
      case 0x08:  // delta velocity
      case 0x09:  // orientation matrix
      case 0x0A:  // orientation quaternion
      case 0x0B:  // orientation update matrix
      case 0x0C:  // Euler angles
      case 0x10:  // stabilised mag (north vector)
      case 0x11:  // stabilised accel (up vector)
      case 0x17:  // ambient pressure
      case 0xD0:  // event source
      case 0xD6:  // reference time delta
        break;    // known, not used for calibration
      default:
        ++counters_.unknown_fields;
        break;
    }
  }
  const bool has_time = time_rank > 0;
  const bool has_data = s.acc_mps2 || s.gyr_radps || s.mag || s.temp_c || s.flags;
  view.carries_sample = has_data;
  sink_->OnFrame(view);
  if (!has_data) return true;

  const std::uint8_t mask = FieldMask(s);
  if (early_t_device_s_) {
    // A packet that would have joined the sample emitted early: wait for the next packet again.
    const bool would_join = has_time ? *early_t_device_s_ == *s.t_device_s : false;
    if (would_join && (mask & early_mask_) == 0) early_ = false;
    early_t_device_s_.reset();
  }
  if (has_pending_) {
    const bool overlap = (s.acc_mps2 && pending_.acc_mps2) || (s.gyr_radps && pending_.gyr_radps) ||
                         (s.mag && pending_.mag);
    const bool joins =
        has_time ? (pending_.t_device_s && *pending_.t_device_s == *s.t_device_s && !overlap)
                 : !overlap;
    if (joins) {
      if (s.acc_mps2) pending_.acc_mps2 = s.acc_mps2;
      if (s.gyr_radps) pending_.gyr_radps = s.gyr_radps;
      if (s.mag) pending_.mag = s.mag;
      if (s.temp_c) pending_.temp_c = s.temp_c;
      pending_.flags |= s.flags;
      ReleaseIfWhole();
      return true;
    }
    Release();
  }
  s.device = device_;
  s.t_host_ns = t_host_ns;
  pending_ = std::move(s);
  has_pending_ = true;
  ReleaseIfWhole();
  return true;
}

std::uint8_t MipDecoder::FieldMask(const Sample& s) {
  return static_cast<std::uint8_t>((s.acc_mps2 ? 1 : 0) | (s.gyr_radps ? 2 : 0) | (s.mag ? 4 : 0) |
                                   (s.temp_c ? 8 : 0));
}

void MipDecoder::ReleaseIfWhole() {
  const std::uint8_t mask = FieldMask(pending_);
  if (!early_ || whole_mask_ == 0 || (mask & whole_mask_) != whole_mask_) return;
  // Only a timestamped sample: without one, the next packet is the only sign of its end.
  if (!pending_.t_device_s) return;
  early_t_device_s_ = pending_.t_device_s;
  early_mask_ = mask;
  Release();
}

void MipDecoder::Release() {
  if (!has_pending_) return;
  has_pending_ = false;
  whole_mask_ |= FieldMask(pending_);
  ++counters_.samples;
  sink_->OnSample(pending_);
}

}  // namespace turncal::drivers
