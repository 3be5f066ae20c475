#include "daemon/state/state_dir.h"

#include <fmt/format.h>

#include <ctime>

namespace turncal::daemon {

namespace fs = std::filesystem;

fs::path StateDir::ActiveCalibration(const std::string& device, const std::string& model) const {
  return CalibrationsDir() / fmt::format("{}.{}.json", device, model);
}

fs::path StateDir::HistoryCalibration(const std::string& device, const std::string& model,
                                      int version) const {
  return HistoryDir() / fmt::format("{}.{}.v{}.json", device, model, version);
}

fs::path StateDir::NoiseProfile(const std::string& device) const {
  return NoiseDir() / (device + ".json");
}

fs::path StateDir::Report(const std::string& device) const {
  return ReportsDir() / (device + ".html");
}

fs::path StateDir::DeviceWriteRecord(const std::string& device) const {
  return DeviceWritesDir() / (device + ".json");
}

std::string UtcStamp() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char stamp[32];
  std::strftime(stamp, sizeof(stamp), "%Y%m%dT%H%M%SZ", &tm);
  return stamp;
}

fs::path UniqueStamped(const fs::path& dir, const std::string& prefix, const std::string& stamp,
                       const std::string& suffix) {
  std::error_code ec;
  fs::path target = dir / (prefix + stamp + suffix);
  for (int n = 2; fs::exists(target, ec); ++n) {
    target = dir / fmt::format("{}{}-{}{}", prefix, stamp, n, suffix);
  }
  return target;
}

}  // namespace turncal::daemon
