#pragma once
// The report's section on what turncal wrote into the device (issue 23;
// daemon/state/device_write_record.h: the state directory's device_writes/DEVICE.UTCTIME.json
// entries): per write or restore, when, which calibration, the outcome, the values written, and the
// verification by measurement with its largest |z|.

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace turncal::report {

// <section class="device-writes" id="device-writes">; "" when there are no entries.
std::string DeviceWritesHtml(const std::vector<nlohmann::json>& entries);

}  // namespace turncal::report
