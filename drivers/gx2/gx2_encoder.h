#pragma once
// GX2 legacy encoders: the continuous-mode command, the stop command and the data replies.

#include <cstdint>
#include <vector>

#include "core/sequencing/sample.h"
#include "drivers/gx2/gx2_decoder.h"

namespace turncal::drivers::gx2 {

// 0xC4 0xC1 0x29 <cmd>: stream replies of `cmd` continuously.
std::vector<std::uint8_t> StartContinuous(std::uint8_t cmd);
// Its acknowledgement: C4 <cmd> timer(4) checksum(2).
std::vector<std::uint8_t> ContinuousAck(std::uint8_t cmd, std::uint32_t timer);
// Stop continuous mode: GX2 `FA`, GX3-25 `FA 75 B4`.
std::vector<std::uint8_t> StopContinuous(bool gx3_25);
// The 0xC2 (accel + rate) or 0xCB (accel + rate + mag) reply for a sample; the timer from
// t_device_s at the options' tick rate.
std::vector<std::uint8_t> Reply(std::uint8_t echo, const Sample& sample, const Gx2Options& options);

}  // namespace turncal::drivers::gx2
