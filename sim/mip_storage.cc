#include "sim/mip_storage.h"

#include <fmt/format.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <system_error>

#include "drivers/mip/mip_stored.h"

namespace turncal::sim {

StoredCalibration MipFactoryDefaults(const StoredCalibration& known) {
  StoredCalibration d;
  if (known.accel_bias) d.accel_bias = Eigen::Vector3d::Zero();
  if (known.gyro_bias) d.gyro_bias = Eigen::Vector3d::Zero();
  if (known.hard_iron) d.hard_iron = Eigen::Vector3d::Zero();
  if (known.soft_iron) d.soft_iron = Eigen::Matrix3d::Identity();
  if (known.transform) d.transform = Eigen::Matrix3d::Identity();
  return d;
}

bool ReadMipNonvolatile(const std::string& path, const StoredCalibration& known,
                        StoredCalibration* out, std::string* error) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return true;
  std::ifstream in(path);
  nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  if (!in.good() && !in.eof()) {
    *error = fmt::format("cannot read the device's non-volatile storage '{}'", path);
    return false;
  }
  if (j.is_discarded() || !j.is_object()) {
    *error = fmt::format("'{}' is not a device's non-volatile storage (a JSON object)", path);
    return false;
  }
  StoredCalibration saved;
  std::string why;
  if (!drivers::mip::ParseStoredCalibration(j, &saved, &why)) {
    *error = fmt::format("'{}': {}", path, why);
    return false;
  }
  StoredCalibration read = *out;
  if (known.accel_bias && saved.accel_bias) read.accel_bias = saved.accel_bias;
  if (known.gyro_bias && saved.gyro_bias) read.gyro_bias = saved.gyro_bias;
  if (known.hard_iron && saved.hard_iron) read.hard_iron = saved.hard_iron;
  if (known.soft_iron && saved.soft_iron) read.soft_iron = saved.soft_iron;
  if (known.transform && saved.transform) read.transform = saved.transform;
  *out = read;
  return true;
}

bool WriteMipNonvolatile(const std::string& path, const StoredCalibration& values,
                         std::string* error) {
  const nlohmann::json j = drivers::mip::StoredCalibrationJson(values, /*nulls=*/false);
  const std::string temporary = path + ".tmp";
  {
    std::ofstream out(temporary, std::ios::trunc);
    out << j.dump(1) << '\n';
    out.flush();
    if (!out) {
      *error = fmt::format("cannot write '{}'", temporary);
      return false;
    }
  }
  std::error_code ec;
  std::filesystem::rename(temporary, path, ec);
  if (ec) {
    *error = fmt::format("cannot rename '{}' to '{}': {}", temporary, path, ec.message());
    return false;
  }
  return true;
}

}  // namespace turncal::sim
