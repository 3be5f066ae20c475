#pragma once
// Xbus encoders: messages, the configuration commands, and MTData2 / legacy MTData messages for
// a sample (simulator, tests, device configuration).

#include <cstdint>
#include <span>
#include <vector>

#include "core/sequencing/sample.h"
#include "drivers/xbus/xbus_decoder.h"

namespace turncal::drivers::xbus {

// FA FF MID LEN [EXT] data CS; data of 255 bytes or more uses the extended length.
std::vector<std::uint8_t> Message(std::uint8_t mid, std::span<const std::uint8_t> data = {},
                                  std::uint8_t bid = 0xFF);

enum Mid : std::uint8_t {
  kReqDid = 0x00,
  kDeviceId = 0x01,
  kGoToMeasurement = 0x10,
  kGoToMeasurementAck = 0x11,
  kReqFwRev = 0x12,
  kReqProductCode = 0x1C,
  kProductCode = 0x1D,
  kSetBaudrate = 0x18,
  kGoToConfig = 0x30,
  kGoToConfigAck = 0x31,
  kMtData = 0x32,
  kMtData2 = 0x36,
  kWakeUp = 0x3E,
  kWakeUpAck = 0x3F,
  kReset = 0x40,
  kError = 0x42,
  kReqOutputMode = 0xD0,
  kReqOutputSettings = 0xD2,
  kSetOutputConfiguration = 0xC0,
  kOutputConfiguration = 0xC1,
};

// The meaning of an Error (0x42) code: "data overflow: more output than the baud rate carries", ...
const char* ErrorMeaning(std::uint8_t code);

// SetOutputConfiguration with (XDI, rate in Hz; 0xFFFF = every packet) pairs (at most 32).
std::vector<std::uint8_t> SetOutputConfiguration(
    std::span<const std::pair<std::uint16_t, std::uint16_t>> outputs);

// One MTData2 item.
void AppendItem(std::uint16_t xdi, std::span<const std::uint8_t> data,
                std::vector<std::uint8_t>* out);
// Values in the number format of `xdi` (XDI & 3).
void AppendValues(std::uint16_t xdi, std::span<const double> values,
                  std::vector<std::uint8_t>* out);

struct MtData2Encoding {
  int format = 0;                         // 0 f32, 1 fp12.20, 2 fp16.32, 3 f64
  VectorFrame frame = VectorFrame::kEnu;  // frame bits of the vector items
};

// An MTData2 message for `sample`: PacketCounter (sample.counter), SampleTimeFine (t_device_s in
// 10 kHz ticks), Temperature, Acceleration, RateOfTurn, MagneticField, StatusWord (clip bits from
// the flags); each only when the sample has it.
std::vector<std::uint8_t> MtData2(const Sample& sample, const MtData2Encoding& encoding = {});

// A legacy MTData message for `sample` in `layout` (sections the sample lacks are zeros; the
// orientation, position, velocity and status sections are zeros).
std::vector<std::uint8_t> MtData(const Sample& sample, const XbusLegacyLayout& layout);

}  // namespace turncal::drivers::xbus
