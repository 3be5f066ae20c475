#include "drivers/gx2/gx2_decoder.h"

#include "core/frames/reference.h"
#include "drivers/bytes.h"
#include "drivers/checksum.h"

namespace turncal::drivers {

std::size_t Gx2Decoder::ReplyLength(std::uint8_t echo) {
  switch (echo) {
    case 0xC2:
      return 31;
    case 0xCB:
      return 43;
    case 0xC4:
      return 8;
    default:
      return 0;
  }
}

Gx2Decoder::Gx2Decoder(std::string device, DecoderSink* sink, Gx2Options options,
                       std::int64_t timeout_ns)
    : ScanningDecoder(kGx2MaxFrame, timeout_ns, sink),
      device_(std::move(device)),
      options_(options) {}

Examination Gx2Decoder::Examine(const std::uint8_t* p, std::size_t n) {
  const std::size_t length = ReplyLength(p[0]);
  if (length == 0) {
    std::size_t skip = 1;
    while (skip < n && ReplyLength(p[skip]) == 0) ++skip;
    return {Examination::kGarbage, skip};
  }
  if (n < length) return {};
  if ((ByteSum(p, length - 2) & 0xFFFF) != LoadU16(p + length - 2)) {
    return {Examination::kBadChecksum, 1};
  }
  return {Examination::kFrame, length};
}

bool Gx2Decoder::Accept(std::span<const std::uint8_t> frame, std::int64_t t_host_ns) {
  const std::uint8_t echo = frame[0];
  FrameView view{Protocol::kGx2, frame, t_host_ns, echo, echo != 0xC4};
  sink_->OnFrame(view);
  if (echo == 0xC4) return true;
  auto f32 = [&](std::size_t at) {
    std::uint32_t v = LoadU32(frame.data() + at);
    if (options_.little_endian_floats) v = __builtin_bswap32(v);
    return static_cast<double>(std::bit_cast<float>(v));
  };
  auto vec = [&](std::size_t at, double scale) -> Eigen::Vector3d {
    return Eigen::Vector3d(f32(at), f32(at + 4), f32(at + 8)) * scale;
  };
  Sample s;
  s.device = device_;
  s.t_host_ns = t_host_ns;
  s.acc_mps2 = vec(1, kStandardGravity_mps2);
  s.gyr_radps = vec(13, 1.0);
  std::size_t timer_at = 25;
  if (echo == 0xCB) {
    s.mag = vec(25, 1.0);
    timer_at = 37;
  }
  const std::uint32_t timer = LoadU32(frame.data() + timer_at);
  s.t_device_s = timer / options_.timer_ticks_per_s;
  ++counters_.samples;
  sink_->OnSample(s);
  return true;
}

}  // namespace turncal::drivers
