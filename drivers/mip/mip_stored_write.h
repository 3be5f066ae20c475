#pragma once
// Writing a stored calibration into a MIP device, safely (issue 23; docs/protocol.md "Writing a
// calibration into the device"):
//
//   1. set to idle (the replies must get through the stream);
//   2. write (function 1) each quantity;
//   3. read every quantity back (function 2) and compare bit for bit with what was written (the
//      device holds f32: the values are compared as the floats sent);
//   4. with `save`, save (function 3) each quantity to non-volatile memory;
//   5. resume.
//
// Any failure after the first write (a NACK, a lost reply, a read-back that differs) rolls back:
// the old values are written again (and saved again when a save had been sent), read back and
// compared. The outcome says exactly what state the device is in: the new values (in RAM, or
// saved), the old values (rolled back and verified), or not known (the rollback failed too: which
// quantities may hold what). The device is resumed in every case (its stream must go on).

#include <cstdint>
#include <string>
#include <vector>

#include "drivers/mip/mip_dialogue.h"

namespace turncal::drivers::mip {

struct StoredWriteStep {
  std::uint8_t descriptor = 0;     // 0x37, 0x38, 0x3A, 0x3B
  std::vector<double> values;      // to write (3, or 9 row-major)
  std::vector<double> old_values;  // what the device holds now (for a rollback)
};

enum class StoredWriteState {
  kUnchanged,   // nothing was written (it failed before the first write took), verified
  kWritten,     // the new values are in use, verified; not saved
  kSaved,       // the new values are in use and saved, verified
  kRolledBack,  // it failed; the old values are back in use (and saved where they had been)
  kUnknown,     // it failed and the rollback did too: see `error` and `log`
};

const char* ToString(StoredWriteState state);

struct StoredWriteOutcome {
  StoredWriteState state = StoredWriteState::kUnchanged;
  std::string error;             // the step that failed (empty when it did not)
  std::string rollback_error;    // the rollback's step that failed
  std::vector<std::string> log;  // every step, in order, with its result (for the journal)
  std::optional<StoredCalibration> read_back;  // the last full read-back
  bool ok() const {
    return state == StoredWriteState::kWritten || state == StoredWriteState::kSaved;
  }
};

StoredWriteOutcome WriteStoredCalibration(Dialogue* dialogue,
                                          const std::vector<StoredWriteStep>& steps, bool save);

// The values of one quantity in a read-back (empty when the device has no such command).
std::vector<double> StoredValues(const StoredCalibration& stored, std::uint8_t descriptor);
// Its inverse: `stored` with `descriptor`'s values replaced by `values` (3, or 9 row-major);
// values of another size leave it as it is.
void SetStoredValues(StoredCalibration* stored, std::uint8_t descriptor,
                     const std::vector<double>& values);
// A quantity's key in turncal's JSON (accel_bias_g, gyro_bias_radps, hard_iron_gauss,
// soft_iron, sensor_to_vehicle) and its unit (g, rad/s, Gauss; "" for the matrices).
const char* StoredQuantityKey(std::uint8_t descriptor);
const char* StoredQuantityUnit(std::uint8_t descriptor);

}  // namespace turncal::drivers::mip
