#pragma once
// The stored calibration of an emulated MIP device (3DM set 0x0C: 0x37 accelerometer bias, 0x38
// gyro bias, 0x3A hard-iron offset, 0x3B soft-iron matrix, 0x33 sensor-to-vehicle transform) and
// what it does to the output, as a real device keeps and applies it (issue 23,
// docs/SIMULATOR.md "Stored calibration"):
//
// - the values in use ("RAM"): what write (function 1), load (4) and default (5) change and read
//   (2) returns; the device applies them before it outputs scaled data;
// - the startup values ("non-volatile"): what save (3) keeps and load and a power-up read. They
//   survive the device's restart when they live in a file (EmulatedIdentity::
//   mip_nonvolatile_path): a JSON object written atomically at every save.
//
// The device's convention (docs/protocol.md "Writing a calibration into the device"): accel out
// = M (raw - bias) (g), gyro out = M (raw - bias) (rad/s), mag out = M S (raw - h) (Gauss; S and
// the transform M row-major as on the wire). Values travel as big-endian f32, so the device holds
// floats: a read returns bit for bit what was written.

#include <optional>
#include <string>

#include "core/sequencing/sample.h"
#include "drivers/mip/mip_dialogue.h"

namespace turncal::sim {

using drivers::mip::StoredCalibration;

// The factory values of the quantities `known` has (a device without a command has no value):
// zero biases and offset, the identity matrix.
StoredCalibration MipFactoryDefaults(const StoredCalibration& known);

// Reads the startup values saved in `path` into `*out` (the quantities `known` has; an entry the
// file lacks keeps `*out`'s). A missing file is not an error: nothing was saved, `*out` is
// unchanged. False with a message for a file that cannot be read or parsed.
bool ReadMipNonvolatile(const std::string& path, const StoredCalibration& known,
                        StoredCalibration* out, std::string* error);

// Writes `values` to `path` atomically (a temporary beside it, then renamed).
bool WriteMipNonvolatile(const std::string& path, const StoredCalibration& values,
                         std::string* error);

}  // namespace turncal::sim
