#pragma once
// Xsens Xbus: scanner and decoder for MTData2 (MID 0x36) and legacy MTData (MID 0x32)
// (PROTOCOLS.md "Xsens Xbus").
//
// MTData2 samples take Acceleration (m/s^2), RateOfTurn (rad/s), MagneticField (a.u.),
// Temperature, PacketCounter (a gap counts lost samples), SampleTimeFine (10 kHz ticks) and
// StatusWord's clip bits, in any of the four number formats; the output frame (ENU/NED/NWU) is
// recorded on the sample with the values as sent. A message whose items do not fill its payload
// exactly is rejected even when its 8-bit checksum passes. Legacy MTData needs its layout
// (OutputMode, OutputSettings) from configuration or from the device.

#include <optional>

#include "drivers/scanning_decoder.h"
#include "drivers/xbus/mtdata2.h"

namespace turncal::drivers {

inline constexpr std::size_t kXbusMaxFrame = 8192;

// The legacy MTData layout.
struct XbusLegacyLayout {
  std::uint16_t output_mode = 0x0002;          // calibrated data
  std::uint32_t output_settings = 0x00000001;  // sample counter, f32

  // The MTData payload size this layout gives, or nullopt (with a message) when it asks for a
  // section this decoder does not read (auxiliary 0x0008, raw 0x4000, ...).
  std::optional<std::size_t> PayloadSize(std::string* error) const;
};

class XbusDecoder final : public ScanningDecoder<XbusDecoder> {
 public:
  // `bus_id`: only messages with this BID are candidates (0xFF: a standalone device; nullopt:
  // any, for a bus master). Filtering on it keeps 0xFA bytes inside data from posing as
  // messages after a corruption.
  // A message cannot take longer than 8192 bytes x 10 bits x 1.5 at 115200 baud (~1.07 s); a
  // header claiming that much is rejected anyway, so the default waits 0.2 s for the rest.
  XbusDecoder(std::string device, DecoderSink* sink,
              std::optional<XbusLegacyLayout> legacy = std::nullopt,
              std::int64_t timeout_ns = 200'000'000,
              std::optional<std::uint8_t> bus_id = std::uint8_t{0xFF});
  Protocol protocol() const override { return legacy_ ? Protocol::kXbusLegacy : Protocol::kXbus; }

  Examination Examine(const std::uint8_t* p, std::size_t n);
  bool Accept(std::span<const std::uint8_t> frame, std::int64_t t_host_ns);
  void Release() {}

  // Payload of an accepted message (after the header, before the checksum).
  static std::span<const std::uint8_t> Payload(std::span<const std::uint8_t> frame);

 private:
  bool AcceptMtData2(std::span<const std::uint8_t> payload, Sample* s);
  bool AcceptLegacy(std::span<const std::uint8_t> payload, Sample* s);
  void CountGap(std::uint16_t counter);

  std::string device_;
  std::optional<XbusLegacyLayout> legacy_;
  std::size_t legacy_size_ = 0;
  std::optional<std::uint16_t> last_counter_;
  std::optional<std::uint16_t> jumped_;  // a counter out of sequence, until the next one
  std::optional<std::uint8_t> bus_id_;
};

}  // namespace turncal::drivers
