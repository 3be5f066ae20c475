// A fixture's session as one capture (sim/fixture_capture.h).

#include "sim/fixture_capture.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace turncal::sim {

bool MergeFixtureCaptures(const std::vector<SimCapture>& units, SimCapture* out,
                          std::string* error) {
  if (units.empty()) {
    *error = "no unit to merge";
    return false;
  }
  const SimCapture& lead = units[0];
  for (std::size_t u = 1; u < units.size(); ++u) {
    const auto& a = lead.session.events;
    const auto& b = units[u].session.events;
    bool same = a.size() == b.size();
    for (std::size_t k = 0; same && k < a.size(); ++k) same = std::abs(a[k].t_s - b[k].t_s) < 1e-9;
    if (!same) {
      *error = fmt::format("unit {}'s poses are not at the first unit's times", u + 1);
      return false;
    }
  }
  out->header = lead.header;
  out->header.devices.clear();
  out->records.clear();
  for (std::size_t u = 0; u < units.size(); ++u) {
    drivers::CaptureDevice device = units[u].header.devices.at(0);
    device.name = fmt::format("imu{}", u + 1);
    out->header.devices.push_back(device);
    // On the first unit's time base; the start-up dialogue before it may begin earlier.
    const std::int64_t shift = lead.offset_ns - units[u].offset_ns;
    for (const auto& r : units[u].records) {
      if (u > 0 && r.type == drivers::RecordType::kEvent) continue;  // the first unit's poses
      drivers::CaptureRecord moved = r;
      moved.device = static_cast<std::uint8_t>(u);
      moved.t_ns = static_cast<std::uint64_t>(
          std::max<std::int64_t>(0, static_cast<std::int64_t>(r.t_ns) + shift));
      out->records.push_back(std::move(moved));
    }
  }
  // In time order; at one time, the order the units were given (a pose after its bytes).
  std::stable_sort(out->records.begin(), out->records.end(),
                   [](const auto& a, const auto& b) { return a.t_ns < b.t_ns; });
  out->session = lead.session;
  out->session_options = lead.session_options;
  out->baud = lead.baud;
  out->offset_ns = lead.offset_ns;
  out->accel_model = lead.accel_model;
  out->mag_model = lead.mag_model;
  out->gyro_model = lead.gyro_model;
  out->mount = lead.mount;
  out->header.note += fmt::format(" (a fixture of {} units)", units.size());
  return true;
}

}  // namespace turncal::sim
