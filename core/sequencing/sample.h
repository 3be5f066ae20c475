#pragma once
// One decoded sensor sample (DESIGN.md "Data flow"). SI units: acc m/s^2, gyr rad/s; mag in the
// device's unit. Optional fields are absent when the frame lacked them.

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <string>

namespace turncal {

enum SampleFlag : std::uint32_t {
  kAccSaturated = 1u << 0,
  kGyrSaturated = 1u << 1,
  kMagSaturated = 1u << 2,
  kStatusError = 1u << 3,  // the device's status word reports an error
  kClipping = 1u << 4,     // the device reports clipping without saying which sensor
};

// The flags' names in JSON output (`turncal decode --json`, the socket's SAMPLE), in bit order.
struct SampleFlagName {
  SampleFlag flag;
  const char* name;
};
inline constexpr SampleFlagName kSampleFlagNames[] = {{kAccSaturated, "acc_saturated"},
                                                      {kGyrSaturated, "gyr_saturated"},
                                                      {kMagSaturated, "mag_saturated"},
                                                      {kStatusError, "status_error"},
                                                      {kClipping, "clipping"}};

// The frame a device expressed its vectors in, when it says (Xbus XDI bits 2-3). Values are
// stored as the device sent them; the frame is recorded so nothing is silently rotated.
enum class VectorFrame : std::uint8_t { kUnknown, kEnu, kNed, kNwu };

struct Sample {
  std::string device;                         // configured device name
  std::optional<double> t_device_s;           // device clock, seconds
  std::int64_t t_host_ns = 0;                 // host monotonic receive time
  std::optional<std::uint32_t> counter;       // device sequence counter
  std::optional<Eigen::Vector3d> acc_mps2;    // specific force, m/s^2
  std::optional<Eigen::Vector3d> gyr_radps;   // angular rate, rad/s
  std::optional<Eigen::Vector3d> mag;         // field, device unit
  std::optional<double> temp_c;               // temperature, deg C
  std::uint32_t flags = 0;                    // SampleFlag bits
  VectorFrame frame = VectorFrame::kUnknown;  // of acc, gyr, mag as sent
};

}  // namespace turncal
