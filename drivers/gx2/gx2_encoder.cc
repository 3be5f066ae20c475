#include "drivers/gx2/gx2_encoder.h"

#include <cmath>

#include "core/frames/reference.h"
#include "drivers/bytes.h"
#include "drivers/checksum.h"

namespace turncal::drivers::gx2 {

namespace {
void AppendChecksum(std::vector<std::uint8_t>* out) { PutU16(out, Gx2Checksum(*out)); }
}  // namespace

std::vector<std::uint8_t> StartContinuous(std::uint8_t cmd) { return {0xC4, 0xC1, 0x29, cmd}; }

std::vector<std::uint8_t> ContinuousAck(std::uint8_t cmd, std::uint32_t timer) {
  std::vector<std::uint8_t> out = {0xC4, cmd};
  PutU32(&out, timer);
  AppendChecksum(&out);
  return out;
}

std::vector<std::uint8_t> StopContinuous(bool gx3_25) {
  return gx3_25 ? std::vector<std::uint8_t>{0xFA, 0x75, 0xB4} : std::vector<std::uint8_t>{0xFA};
}

std::vector<std::uint8_t> Reply(std::uint8_t echo, const Sample& s, const Gx2Options& options) {
  std::vector<std::uint8_t> out = {echo};
  auto f32 = [&](double v) {
    std::uint32_t bits = std::bit_cast<std::uint32_t>(static_cast<float>(v));
    if (options.little_endian_floats) bits = __builtin_bswap32(bits);
    PutU32(&out, bits);
  };
  auto vec = [&](const std::optional<Eigen::Vector3d>& v, double scale) {
    const Eigen::Vector3d x = v.value_or(Eigen::Vector3d::Zero()) * scale;
    for (int i = 0; i < 3; ++i) f32(x[i]);
  };
  vec(s.acc_mps2, 1.0 / kStandardGravity_mps2);
  vec(s.gyr_radps, 1.0);
  if (echo == 0xCB) vec(s.mag, 1.0);
  const double ticks = s.t_device_s.value_or(0.0) * options.timer_ticks_per_s;
  PutU32(&out, static_cast<std::uint32_t>(std::fmod(std::llround(ticks), 4294967296.0)));
  AppendChecksum(&out);
  return out;
}

}  // namespace turncal::drivers::gx2
