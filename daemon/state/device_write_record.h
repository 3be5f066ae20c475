#pragma once
// What turncald keeps of the writes into a device's stored calibration (issue 23,
// docs/protocol.md "Writing a calibration into the device"): the record of what is in effect
// and the history of every write, in the state directory. (How a write is verified by
// measurement: daemon/device_write/write_verification.h.)
//
// In the state directory:
//   device_writes/DEVICE.json          what is in effect: the values the device holds, those the
//                                      last write or restore replaced, and the stored values the
//                                      station's calibrations see the device's output in
//                                      (`as_if`: what it held before turncal's first write;
//                                      `restore` writes them back)
//   device_writes/DEVICE.UTCTIME.json  every write and restore: the plan, every step, the
//                                      outcome, the verification (never rewritten)
//
// After a write the device outputs m' (its new stored values applied), while the station's poses
// and calibrations were made from its output m with `as_if` applied. turncald re-expresses every
// sample of the device in `as_if` (drivers/mip/mip_stored.h ReexpressMipOutput) before the
// station sees it, so the session goes on unchanged and the corrected stream is the calibration's
// correction of the device's new output; the `raw` stream shows what the device sends.

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/estimation/pose_record.h"
#include "core/modeling/measurement_model.h"
#include "core/sequencing/sample.h"
#include "drivers/mip/mip_dialogue.h"

namespace turncal::daemon {

using drivers::mip::StoredCalibration;

// Equal, or both absent.
bool SameStoredVector(const std::optional<Eigen::Vector3d>& a,
                      const std::optional<Eigen::Vector3d>& b);
bool SameStoredCalibration(const StoredCalibration& a, const StoredCalibration& b);

struct DeviceWriteRecord {
  std::string device, serial;
  std::string model;  // the calibration written last ("" after a restore to `as_if`)
  int version = 0;
  std::string time;             // UTC of the last operation
  std::string operation;        // "write" or "restore"
  StoredCalibration as_if;      // the stored values the station's calibrations see the output in
  StoredCalibration in_device;  // what the device holds after the last operation
  StoredCalibration replaced;   // what the last operation replaced (restore writes these back)
  bool saved = false;           // the last operation saved to non-volatile memory
  // A write since the device held `as_if` saved to non-volatile memory (a restore then saves
  // too, so that the device starts with `as_if` again).
  bool nonvolatile_changed = false;
  // What a write under way puts into the device (written before it starts): a turncald that
  // stops mid-write finds, at the device's next dialogue, whether the device holds these.
  std::optional<StoredCalibration> pending;
  // The re-expression is needed while the device holds other values than `as_if`.
  bool reexpress() const { return !SameStoredCalibration(in_device, as_if); }
};

nlohmann::json ToJson(const DeviceWriteRecord& record);
bool ParseDeviceWriteRecord(const nlohmann::json& j, DeviceWriteRecord* out, std::string* error);

// device_writes/DEVICE.json: *exists false (and true returned) when there is none. False with a
// message when it cannot be read or parsed.
bool ReadDeviceWriteRecord(const std::string& state_dir, const std::string& device,
                           DeviceWriteRecord* record, bool* exists, std::string* error);
bool WriteDeviceWriteRecord(const std::string& state_dir, const DeviceWriteRecord& record,
                            std::string* error);
// device_writes/DEVICE.UTCTIME.json (a suffix -2, -3 ... when that second has one); *path
// receives it.
bool WriteDeviceWriteHistory(const std::string& state_dir, const std::string& device,
                             const nlohmann::json& entry, std::string* path, std::string* error);

// Every entry of device_writes/DEVICE.UTCTIME.json, oldest first (unreadable ones are skipped).
std::vector<nlohmann::json> ReadDeviceWriteHistory(const std::string& state_dir,
                                                   const std::string& device);

}  // namespace turncal::daemon
