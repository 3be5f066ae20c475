#pragma once
// MicroStrain MIP: scanner and decoder (PROTOCOLS.md "MicroStrain MIP").
//
// Samples come from the sensor data set 0x80: scaled accel (g, converted to m/s^2), gyro
// (rad/s), mag (Gauss), over-range bits as sample flags, the mean of the temperature statistics,
// and the device time from 0xD5 (reference timestamp, preferred), 0x0E (16 us ticks) or
// 0x12/0xD3 (GPS time of week). A sample split over several packets is grouped: a packet without
// a timestamp joins the waiting sample when it adds fields the sample lacks; a packet with a
// timestamp joins it only when the timestamp is the same. Other sets (filter 0x82, system 0xA0,
// command replies) are reported as frames and otherwise ignored.

#include <memory>
#include <optional>

#include "core/reference.h"
#include "drivers/scanning_decoder.h"

namespace turncal::drivers {

inline constexpr std::size_t kMipMaxFrame = 261;

class MipDecoder final : public ScanningDecoder<MipDecoder> {
 public:
  // `timeout_ns`: drop an incomplete packet after this long (default: 261 bytes x 10 bits x 1.5
  // at 115200 baud, about 34 ms).
  MipDecoder(std::string device, DecoderSink* sink, std::int64_t timeout_ns = 34'000'000);
  Protocol protocol() const override { return Protocol::kMip; }

  Examination Examine(const std::uint8_t* p, std::size_t n);
  bool Accept(std::span<const std::uint8_t> frame, std::int64_t t_host_ns);
  void Release();

 private:
  std::string device_;
  Sample pending_;
  bool has_pending_ = false;
};

}  // namespace turncal::drivers
