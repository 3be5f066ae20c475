#pragma once
// MicroStrain legacy single-byte protocol (3DM-GX2, 3DM-GX3-25; PROTOCOLS.md): fixed-length
// replies that start with the echoed command byte and end with a 16-bit sum. No sync bytes and no
// length: a candidate starts at any byte equal to a known reply's echo, and on a bad checksum the
// scan slides one byte.
//
// Replies read: 0xC2 accel + rate (31 B), 0xCB accel + rate + mag (43 B), 0xC4 continuous-mode
// acknowledgement (8 B). Units on the wire: g, rad/s, Gauss; the timer is u32 ticks at a rate
// that depends on the device model (GX2 19 660 800 /s, GX3-25 62 500 /s).

#include "drivers/scanning_decoder.h"

namespace turncal::drivers {

inline constexpr std::size_t kGx2MaxFrame = 43;

struct Gx2Options {
  double timer_ticks_per_s = 19'660'800.0;  // 3DM-GX2; 62 500 for the GX3-25
  bool little_endian_floats = false;        // GX3-25 firmware >= 1.1.27, 0xDB flags bit 4
};

class Gx2Decoder final : public ScanningDecoder<Gx2Decoder> {
 public:
  Gx2Decoder(std::string device, DecoderSink* sink, Gx2Options options = {},
             std::int64_t timeout_ns = 10'000'000);
  Protocol protocol() const override { return Protocol::kGx2; }

  Examination Examine(const std::uint8_t* p, std::size_t n);
  bool Accept(std::span<const std::uint8_t> frame, std::int64_t t_host_ns);
  void Release() {}

  // Reply length for an echo byte, 0 when it starts no reply this decoder reads.
  static std::size_t ReplyLength(std::uint8_t echo);

 private:
  std::string device_;
  Gx2Options options_;
};

}  // namespace turncal::drivers
