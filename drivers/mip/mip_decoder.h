#pragma once
// MicroStrain MIP: scanner and decoder (PROTOCOLS.md "MicroStrain MIP").
//
// Samples come from the sensor data set 0x80: scaled accel (g, converted to m/s^2), gyro
// (rad/s), mag (Gauss), over-range bits as sample flags, the mean of the temperature statistics,
// and the device time from 0xD5 (reference timestamp, preferred), 0x0E (16 us ticks) or
// 0x12/0xD3 (GPS time of week). A sample split over several packets is grouped: a packet without
// a timestamp joins the waiting sample when it adds fields the sample lacks; a packet with a
// timestamp joins it only when the timestamp is the same. A sample is normally emitted when the
// next packet shows it complete; once the stream has shown which fields make a whole sample (the
// union of the fields of the samples emitted so far), a sample that has them all is emitted at
// once, without waiting a sample period for the next packet (the daemon's output latency). Should
// a later packet still join such a sample (a device sending more fields than before), the sample
// has gone out in two parts and early emission stops for the rest of the stream. Other sets (filter
// 0x82, system 0xA0, command replies) are reported as frames and otherwise ignored.

#include <memory>
#include <optional>

#include "core/frames/reference.h"
#include "drivers/scanning_decoder.h"

namespace turncal::drivers {

inline constexpr std::size_t kMipMaxFrame = 261;

class MipDecoder final : public ScanningDecoder<MipDecoder> {
 public:
  // `timeout_ns`: drop an incomplete packet after this long (default: 261 bytes x 10 bits x 1.5
  // at 115200 baud, about 34 ms).
  // `early`: emit whole samples at once (above); false: always wait for the next packet.
  MipDecoder(std::string device, DecoderSink* sink, std::int64_t timeout_ns = 34'000'000,
             bool early = true);
  Protocol protocol() const override { return Protocol::kMip; }

  Examination Examine(const std::uint8_t* p, std::size_t n);
  bool Accept(std::span<const std::uint8_t> frame, std::int64_t t_host_ns);
  void Release();

 private:
  void ReleaseIfWhole();
  static std::uint8_t FieldMask(const Sample& s);

  std::string device_;
  Sample pending_;
  bool has_pending_ = false;
  std::uint8_t whole_mask_ = 0;  // fields of every sample emitted so far
  bool early_ = true;            // emit a sample with all of them at once
  // The last sample emitted early, to notice a packet that would have joined it.
  std::optional<double> early_t_device_s_;
  std::uint8_t early_mask_ = 0;
};

}  // namespace turncal::drivers
