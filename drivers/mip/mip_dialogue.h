#pragma once
// The MIP configuration dialogue (PROTOCOLS.md "Commands"): set to idle with retries (a reply
// lost among streaming data is common), device information, IMU base rate, message format,
// enable stream, resume, and the calibration the device applies itself before output (stored
// accel/gyro bias, hard- and soft-iron), which must be recorded with every calibration.

#include <Eigen/Core>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "drivers/exchange.h"

namespace turncal::drivers::mip {

struct DeviceInfo {
  std::uint16_t firmware = 0;
  std::string model_name, model_number, serial, lot, options;
};

// Absent entries: the device does not know that command (NACK "unknown command").
struct StoredCalibration {
  std::optional<Eigen::Vector3d> accel_bias;  // g
  std::optional<Eigen::Vector3d> gyro_bias;   // rad/s
  std::optional<Eigen::Vector3d> hard_iron;   // Gauss
  std::optional<Eigen::Matrix3d> soft_iron;
  // 0x33: the sensor-to-vehicle transform (direction cosine matrix, row-major): the device turns
  // every scaled output by it, after its biases and soft and hard iron.
  std::optional<Eigen::Matrix3d> transform;
};

struct Configured {
  DeviceInfo info;
  std::uint16_t base_rate_hz = 0;
  std::uint16_t decimation = 0;
  StoredCalibration stored;
};

// "unknown command", "bad checksum", "bad parameter", "failed", "timeout".
const char* NackMeaning(std::uint8_t code);
// A stored quantity's name: "accel bias" (0x37), "gyro bias" (0x38), "hard-iron offset" (0x3A),
// "soft-iron matrix" (0x3B), "sensor-to-vehicle transform" (0x33), "stored value" otherwise.
const char* StoredQuantityName(std::uint8_t descriptor);

class Dialogue {
 public:
  explicit Dialogue(ByteLink* link, ExchangeOptions options = {});

  bool SetToIdle(std::string* error);
  std::optional<DeviceInfo> GetDeviceInfo(std::string* error);
  std::optional<std::uint16_t> GetImuBaseRate(std::string* error);
  bool SetImuMessageFormat(std::span<const std::pair<std::uint8_t, std::uint16_t>> descriptors,
                           std::string* error);
  bool EnableStream(std::uint8_t data_set, bool on, std::string* error);
  bool Resume(std::string* error);
  std::optional<StoredCalibration> ReadStoredCalibration(std::string* error);
  // Write (function 1) one stored quantity (0x37, 0x38, 0x3A: 3 values; 0x3B: 9, row-major),
  // or save (3), load (4) or default (5) it. `nack_code` (when not null) gets the reply's code
  // (0xFF: no reply).
  bool WriteStored(std::uint8_t descriptor, std::span<const double> values, std::string* error,
                   std::uint8_t* nack_code = nullptr);
  bool StoredFunction(std::uint8_t descriptor, std::uint8_t function, std::string* error,
                      std::uint8_t* nack_code = nullptr);

  // The whole sequence: idle, device info, base rate, accel+gyro+mag at the decimation closest to
  // `rate_hz`, stored calibration, enable the sensor stream, resume. nullopt with the step that
  // failed.
  std::optional<Configured> Configure(double rate_hz, std::string* error);

 private:
  // Sends a command and waits for its ACK/NACK; the reply's data fields are returned.
  std::optional<std::vector<std::pair<std::uint8_t, std::vector<std::uint8_t>>>> Command(
      const std::vector<std::uint8_t>& request, const std::string& what, std::string* error,
      std::uint8_t* nack_code = nullptr);

  ByteLink* link_;
  ExchangeOptions options_;
};

}  // namespace turncal::drivers::mip
