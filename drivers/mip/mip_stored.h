#pragma once
// A MIP device's stored calibration (3DM 0x37 accelerometer bias, 0x38 gyro bias, 0x3A hard-iron
// offset, 0x3B soft-iron matrix): what it does to the output, and its JSON.
//
// The device's convention (docs/protocol.md "Writing a calibration into the device"): accel out
// = M (raw - bias) (g), gyro out = M (raw - bias) (rad/s), mag out = M S (raw - h) (Gauss), M the
// sensor-to-vehicle transform (0x33; the identity when the device has none).
//
// The JSON, one shape wherever it is kept: the identity a
// configuration dialogue records ("stored_calibration"), the simulated device's non-volatile
// file, and the state directory's record of a write into the device (issue 23).
//
//   {"accel_bias_g":[x,y,z], "gyro_bias_radps":[x,y,z], "hard_iron_gauss":[x,y,z],
//    "soft_iron":[[r0],[r1],[r2]], "sensor_to_vehicle":[[r0],[r1],[r2]]}
//
// A quantity the device has no command for is null (or absent; the transform is left out then).

#include <nlohmann/json.hpp>
#include <string>

#include "core/sequencing/sample.h"
#include "drivers/mip/mip_dialogue.h"

namespace turncal::drivers::mip {

// With `nulls`, a quantity the device lacks is written as null; otherwise it is left out.
nlohmann::json StoredCalibrationJson(const StoredCalibration& stored, bool nulls = true);

// Reads what `j` holds (an absent or null entry stays nullopt). False with a message naming the
// entry when one is present but not 3 (or 3 x 3) finite numbers, or `j` is not an object.
bool ParseStoredCalibration(const nlohmann::json& j, StoredCalibration* out, std::string* error);

// A sample the device output with `applied` in use, as it would have output it with `as_if`: each
// triad's raw value recovered through `applied` and corrected through `as_if` (the simulated
// device applies a new stored calibration this way; turncald re-expresses a device's output after
// a write in the stored values its calibrations were made with). Triads whose values are the same
// are left bit for bit as they are. A quantity the device lacks counts as zero (identity).
void ReexpressMipOutput(const StoredCalibration& applied, const StoredCalibration& as_if,
                        Sample* s);
// The linear part of that re-expression for one triad: M' M^-1 (accelerometer, gyroscope), or
// M' S' S^-1 M^-1 (magnetometer), primes of `as_if`.
Eigen::Matrix3d ReexpressLinear(const StoredCalibration& applied, const StoredCalibration& as_if,
                                bool magnetometer);

}  // namespace turncal::drivers::mip
