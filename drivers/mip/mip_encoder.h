#pragma once
// MIP encoders: packets, fields, the commands the device dialogue sends, and sensor-data packets
// (for the simulator and tests). Every packet carries its checksum.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/sequencing/sample.h"

namespace turncal::drivers::mip {

struct Field {
  std::uint8_t descriptor = 0;
  std::vector<std::uint8_t> data;  // at most 253 bytes
};

// 75 65 set len fields ck1 ck2. The fields must fit in 255 bytes.
std::vector<std::uint8_t> Packet(std::uint8_t set, std::span<const Field> fields);

// Commands (base set 0x01, 3DM set 0x0C).
std::vector<std::uint8_t> Ping();
std::vector<std::uint8_t> SetToIdle();
std::vector<std::uint8_t> Resume();
std::vector<std::uint8_t> GetDeviceInfo();
std::vector<std::uint8_t> GetImuBaseRate();
// IMU message format: write (function 1) the descriptors with their decimations.
std::vector<std::uint8_t> ImuMessageFormat(
    std::span<const std::pair<std::uint8_t, std::uint16_t>> descriptors);
// Enable or disable the stream of a data set (3DM 0x11, function 1).
std::vector<std::uint8_t> EnableStream(std::uint8_t data_set, bool on);
// Read (function 2) a stored calibration: 0x37 accel bias, 0x38 gyro bias, 0x3A hard iron,
// 0x3B soft iron.
std::vector<std::uint8_t> ReadStored(std::uint8_t descriptor);
// Write (function 1) a stored calibration: 0x37 / 0x38 / 0x3A three values, 0x3B nine
// (row-major), each as a big-endian f32 (the values are rounded to float, as the device holds
// them).
std::vector<std::uint8_t> WriteStored(std::uint8_t descriptor, std::span<const double> values);
// Save (3), load (4) or default (5) a stored calibration.
std::vector<std::uint8_t> StoredFunction(std::uint8_t descriptor, std::uint8_t function);

// A reply: the ACK/NACK field 04 F1 <echo> <code> and optional data fields.
std::vector<std::uint8_t> Reply(std::uint8_t set, std::uint8_t echo, std::uint8_t code,
                                std::span<const Field> data = {});

// A sensor-data packet (set 0x80) for `sample`: 0xD5 reference time (when t_device_s is set,
// nanoseconds), scaled accel (g), gyro, mag, over-range bits from the sample's flags, and the
// temperature as statistics (min = max = mean) when present.
std::vector<std::uint8_t> SensorPacket(const Sample& sample);

}  // namespace turncal::drivers::mip
