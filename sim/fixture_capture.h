#pragma once
// A fixture's session as one capture (issue 38): several simulated units on one table, each its
// own capture (its own mount, seed and truth) of the same pose plan, merged into one .tcap that
// `turncald --replay` runs as a station with several devices: "imu1", "imu2", ... The first
// unit's pose announcements go to every device; every unit's bytes are shifted onto the first's
// time base (their session time 0 at the same capture time).

#include <string>
#include <vector>

#include "sim/capture.h"

namespace turncal::sim {

// The four mounts a fixture's units take in turn (`turncal plan-vs-cube --units N`, the pipeline
// Monte Carlo's --units): along the table, rotated 90 deg about z, upside down, on its side.
inline constexpr const char* kFixtureMounts[] = {"+x+y+z", "-y+x+z", "+x-y-z", "+z+x+y"};

// `units` (at least one; each one device, simulated with the same pose plan and dwell) merged
// into *out: the first unit's header, records and session with every unit's device and bytes.
// False with a message when the units' plans differ in their pose times.
bool MergeFixtureCaptures(const std::vector<SimCapture>& units, SimCapture* out,
                          std::string* error);

}  // namespace turncal::sim
