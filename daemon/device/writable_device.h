#pragma once
// What writing a calibration into a device (daemon/device_write/device_writer.h) needs of the
// device: its name and protocol, its state, what it said about itself in its last dialogue, and a
// write of its stored calibration. turncald's LiveDevice (daemon/device/live_device.h) is one; the
// device writer's tests drive the device emulator (sim/device.h) through another.

#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "drivers/device_spec.h"
#include "drivers/mip/mip_stored_write.h"

namespace turncal::daemon {

class WritableDevice {
 public:
  // Runs on the loop with the write's outcome and the identity after it (null with
  // `configure_error` when the dialogue after the write failed).
  using StoredWriteDone =
      std::function<void(const drivers::mip::StoredWriteOutcome& outcome,
                         const nlohmann::json& identity, const std::string& configure_error)>;

  virtual ~WritableDevice() = default;
  virtual const drivers::DeviceSpec& spec() const = 0;
  // "streaming", "configuring", "writing", ... (LiveDevice's states).
  virtual const std::string& state() const = 0;
  // What the device said about itself in its last dialogue (null before one): "serial",
  // "rate_hz", "stored_calibration", ...
  virtual nlohmann::json identity() const = 0;
  // Writes a stored calibration (drivers/mip/mip_stored_write.h) and configures the device
  // again; `done` runs on the loop. False with a message when the device cannot be written now.
  virtual bool RunStoredWrite(std::vector<drivers::mip::StoredWriteStep> steps, bool save,
                              StoredWriteDone done, std::string* error) = 0;
};

}  // namespace turncal::daemon
