#pragma once
// A fixture of many units on one table (issue 38; docs/BATCH.md): its slots and each slot's
// nominal mount, and which slot (or which mount) each [[device]] has.
//
//   [fixture]                       # in turncald.toml, or in a file of its own:
//   name = "cube8"                  #   [fixture] file = "cube8.toml" (relative to turncald.toml)
//   [[fixture.slot]]                #   holding name = ... and [[slot]] tables
//   name = "1"
//   mount = "+x+y+z"                # the case's axes along the table's, or [x, y, z] degrees
//
//   [[device]]
//   name = "imu1"
//   slot = "1"                      # its mount the slot's; or mount = "-y+x+z" without a fixture
//
// Every key is checked as in the rest of the file; a slot named twice, a device in a slot the
// fixture has not, two devices in one slot, or a device with both a slot and a mount are errors
// naming the line.

#include <toml++/toml.h>

#include <string>
#include <vector>

#include "core/frames/rotations.h"
#include "daemon/station/station.h"

namespace turncal::daemon {

struct FixtureSlot {
  std::string name;
  Mat3<double> mount = Mat3<double>::Identity();
};

struct Fixture {
  std::string name;  // the fixture's (empty: none configured)
  std::string file;  // where its slots were read ("": turncald.toml itself)
  // The batch id a new session takes ([fixture] batch in turncald.toml, never in the fixture's
  // own file: the fixture outlives its batches); "": FIXTURE-UTCTIME (daemon/state/batch_file.h).
  std::string batch;
  std::vector<FixtureSlot> slots;
  const FixtureSlot* Find(const std::string& slot) const;
};

// A mount: "-y+x+z" (the case's axes along the table's) or [x, y, z] degrees (R1 R2 R3,
// core/frames/mount.h). `key` names it in messages.
bool ParseMountNode(const toml::node& node, const char* key, const std::string& source,
                    Mat3<double>* mount, std::string* error);

// [fixture] of the configuration `source` (its slots inline, or read from `file` relative to
// the configuration's folder).
bool ParseFixture(const toml::table& table, const std::string& source, Fixture* out,
                  std::string* error);

// A [[device]]'s `slot` or `mount` into `own` (its slot's mount from `fixture`); `taken` holds
// the slots of the devices before it (a slot holds one unit).
bool ParseDeviceMount(const toml::table& device, const std::string& device_name,
                      const Fixture& fixture, const std::string& source,
                      std::vector<std::string>* taken, DeviceModelOptions* own, std::string* error);

}  // namespace turncal::daemon
