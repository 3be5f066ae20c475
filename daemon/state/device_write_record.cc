#include "daemon/state/device_write_record.h"

#include <fmt/format.h>

#include <filesystem>
#include <fstream>

#include "daemon/state/atomic_file.h"
#include "daemon/state/state_dir.h"
#include "drivers/mip/mip_stored.h"

namespace turncal::daemon {

namespace fs = std::filesystem;

bool SameStoredVector(const std::optional<Eigen::Vector3d>& a,
                      const std::optional<Eigen::Vector3d>& b) {
  return a.has_value() == b.has_value() && (!a || *a == *b);
}

bool SameStoredCalibration(const StoredCalibration& a, const StoredCalibration& b) {
  return SameStoredVector(a.accel_bias, b.accel_bias) &&
         SameStoredVector(a.gyro_bias, b.gyro_bias) && SameStoredVector(a.hard_iron, b.hard_iron) &&
         a.soft_iron.has_value() == b.soft_iron.has_value() &&
         (!a.soft_iron || *a.soft_iron == *b.soft_iron) &&
         a.transform.has_value() == b.transform.has_value() &&
         (!a.transform || *a.transform == *b.transform);
}

nlohmann::json ToJson(const DeviceWriteRecord& r) {
  using drivers::mip::StoredCalibrationJson;
  return {{"schema", 1},
          {"class", "DEVICE_WRITE_RECORD"},
          {"device", r.device},
          {"serial", r.serial},
          {"model", r.model},
          {"version", r.version},
          {"time", r.time},
          {"operation", r.operation},
          {"saved", r.saved},
          {"nonvolatile_changed", r.nonvolatile_changed},
          {"as_if", StoredCalibrationJson(r.as_if)},
          {"in_device", StoredCalibrationJson(r.in_device)},
          {"replaced", StoredCalibrationJson(r.replaced)},
          {"pending", r.pending ? StoredCalibrationJson(*r.pending) : nlohmann::json()}};
}

bool ParseDeviceWriteRecord(const nlohmann::json& j, DeviceWriteRecord* out, std::string* error) {
  if (!j.is_object() || j.value("class", "") != "DEVICE_WRITE_RECORD") {
    *error = "not a device write record (class DEVICE_WRITE_RECORD)";
    return false;
  }
  DeviceWriteRecord r;
  try {
    r.device = j.at("device").get<std::string>();
    r.serial = j.at("serial").get<std::string>();
    r.model = j.value("model", "");
    r.version = j.value("version", 0);
    r.time = j.value("time", "");
    r.operation = j.value("operation", "");
    r.saved = j.value("saved", false);
    r.nonvolatile_changed = j.value("nonvolatile_changed", false);
  } catch (const nlohmann::json::exception& e) {
    *error = std::string("a device write record: ") + e.what();
    return false;
  }
  std::string why;
  for (const auto& [key, into] :
       {std::pair{"as_if", &r.as_if}, std::pair{"in_device", &r.in_device},
        std::pair{"replaced", &r.replaced}}) {
    if (!j.contains(key) || !drivers::mip::ParseStoredCalibration(j[key], into, &why)) {
      *error = fmt::format("a device write record's \"{}\": {}", key,
                           j.contains(key) ? why : std::string("missing"));
      return false;
    }
  }
  if (j.contains("pending") && !j["pending"].is_null()) {
    StoredCalibration pending;
    if (!drivers::mip::ParseStoredCalibration(j["pending"], &pending, &why)) {
      *error = "a device write record's \"pending\": " + why;
      return false;
    }
    r.pending = pending;
  }
  *out = r;
  return true;
}

bool ReadDeviceWriteRecord(const std::string& state_dir, const std::string& device,
                           DeviceWriteRecord* record, bool* exists, std::string* error) {
  const fs::path path = StateDir(state_dir).DeviceWriteRecord(device);
  std::error_code ec;
  *exists = fs::exists(path, ec);
  if (!*exists) return true;
  std::ifstream in(path);
  const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  std::string why;
  if (j.is_discarded() || !ParseDeviceWriteRecord(j, record, &why)) {
    *error = fmt::format("'{}': {}", path.string(), j.is_discarded() ? "not JSON" : why);
    return false;
  }
  return true;
}

bool WriteDeviceWriteRecord(const std::string& state_dir, const DeviceWriteRecord& record,
                            std::string* error) {
  std::error_code ec;
  fs::create_directories(StateDir(state_dir).DeviceWritesDir(), ec);
  return WriteFileAtomically(StateDir(state_dir).DeviceWriteRecord(record.device).string(),
                             ToJson(record).dump(1) + "\n", error);
}

bool WriteDeviceWriteHistory(const std::string& state_dir, const std::string& device,
                             const nlohmann::json& entry, std::string* path, std::string* error) {
  std::error_code ec;
  fs::create_directories(StateDir(state_dir).DeviceWritesDir(), ec);
  *path = UniqueStamped(StateDir(state_dir).DeviceWritesDir(), device + ".", UtcStamp(), ".json")
              .string();
  return WriteFileAtomically(*path, entry.dump(1) + "\n", error);
}

std::vector<nlohmann::json> ReadDeviceWriteHistory(const std::string& state_dir,
                                                   const std::string& device) {
  std::vector<std::string> paths;
  std::error_code ec;
  const std::string prefix = device + ".";
  for (const auto& entry : fs::directory_iterator(StateDir(state_dir).DeviceWritesDir(), ec)) {
    const std::string name = entry.path().filename().string();
    // DEVICE.UTCTIME.json and DEVICE.UTCTIME-N.json; not DEVICE.json (the record).
    if (name.rfind(prefix, 0) == 0 && name != device + ".json" && name.size() > prefix.size() &&
        name[prefix.size()] >= '0' && name[prefix.size()] <= '9') {
      paths.push_back(entry.path().string());
    }
  }
  // By time, then by the -N suffix (DEVICE.T.json, DEVICE.T-2.json, ...).
  const auto key = [&](const std::string& path) {
    std::string stem = fs::path(path).stem().string().substr(prefix.size());
    int n = 1;
    if (const auto dash = stem.find('-'); dash != std::string::npos) {
      n = std::atoi(stem.c_str() + dash + 1);
      stem.resize(dash);
    }
    return std::pair(stem, n);
  };
  std::sort(paths.begin(), paths.end(),
            [&](const std::string& a, const std::string& b) { return key(a) < key(b); });
  std::vector<nlohmann::json> entries;
  for (const auto& path : paths) {
    std::ifstream in(path);
    nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
    if (!j.is_discarded() && j.is_object()) entries.push_back(std::move(j));
  }
  return entries;
}

}  // namespace turncal::daemon
