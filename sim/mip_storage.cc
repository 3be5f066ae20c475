#include "sim/mip_storage.h"

#include <fmt/format.h>

#include <Eigen/LU>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <system_error>

#include "core/frames/reference.h"

namespace turncal::sim {

namespace {

using Json = nlohmann::json;

Json VectorJson(const Eigen::Vector3d& v) { return Json::array({v.x(), v.y(), v.z()}); }

bool ReadVector(const Json& j, Eigen::Vector3d* out) {
  if (!j.is_array() || j.size() != 3) return false;
  for (int i = 0; i < 3; ++i) {
    if (!j[static_cast<std::size_t>(i)].is_number()) return false;
    (*out)[i] = j[static_cast<std::size_t>(i)].get<double>();
  }
  return out->allFinite();
}

bool ReadMatrix(const Json& j, Eigen::Matrix3d* out) {
  if (!j.is_array() || j.size() != 3) return false;
  for (int r = 0; r < 3; ++r) {
    Eigen::Vector3d row;
    if (!ReadVector(j[static_cast<std::size_t>(r)], &row)) return false;
    out->row(r) = row.transpose();
  }
  return true;
}

bool Same(const std::optional<Eigen::Vector3d>& a, const std::optional<Eigen::Vector3d>& b) {
  return a.value_or(Eigen::Vector3d::Zero()) == b.value_or(Eigen::Vector3d::Zero());
}

}  // namespace

StoredCalibration MipFactoryDefaults(const StoredCalibration& known) {
  StoredCalibration d;
  if (known.accel_bias) d.accel_bias = Eigen::Vector3d::Zero();
  if (known.gyro_bias) d.gyro_bias = Eigen::Vector3d::Zero();
  if (known.hard_iron) d.hard_iron = Eigen::Vector3d::Zero();
  if (known.soft_iron) d.soft_iron = Eigen::Matrix3d::Identity();
  return d;
}

bool ReadMipNonvolatile(const std::string& path, const StoredCalibration& known,
                        StoredCalibration* out, std::string* error) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return true;
  std::ifstream in(path);
  Json j = Json::parse(in, nullptr, false);
  if (!in.good() && !in.eof()) {
    *error = fmt::format("cannot read the device's non-volatile storage '{}'", path);
    return false;
  }
  if (j.is_discarded() || !j.is_object()) {
    *error = fmt::format("'{}' is not a device's non-volatile storage (a JSON object)", path);
    return false;
  }
  StoredCalibration read = *out;
  const auto vector = [&](const char* key, bool has, std::optional<Eigen::Vector3d>* v) {
    if (!has || !j.contains(key)) return true;
    Eigen::Vector3d x;
    if (!ReadVector(j[key], &x)) return false;
    *v = x;
    return true;
  };
  bool ok = vector("accel_bias_g", known.accel_bias.has_value(), &read.accel_bias) &&
            vector("gyro_bias_radps", known.gyro_bias.has_value(), &read.gyro_bias) &&
            vector("hard_iron_gauss", known.hard_iron.has_value(), &read.hard_iron);
  if (ok && known.soft_iron && j.contains("soft_iron")) {
    Eigen::Matrix3d m;
    ok = ReadMatrix(j["soft_iron"], &m);
    if (ok) read.soft_iron = m;
  }
  if (!ok) {
    *error = fmt::format("'{}': a stored value is not 3 (or 3 x 3) finite numbers", path);
    return false;
  }
  *out = read;
  return true;
}

bool WriteMipNonvolatile(const std::string& path, const StoredCalibration& values,
                         std::string* error) {
  Json j = Json::object();
  if (values.accel_bias) j["accel_bias_g"] = VectorJson(*values.accel_bias);
  if (values.gyro_bias) j["gyro_bias_radps"] = VectorJson(*values.gyro_bias);
  if (values.hard_iron) j["hard_iron_gauss"] = VectorJson(*values.hard_iron);
  if (values.soft_iron) {
    j["soft_iron"] = Json::array();
    for (int r = 0; r < 3; ++r) j["soft_iron"].push_back(VectorJson(values.soft_iron->row(r)));
  }
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

void ApplyMipStored(const StoredCalibration& carried, const StoredCalibration& now, Sample* s) {
  if (s->acc_mps2 && !Same(carried.accel_bias, now.accel_bias)) {
    const Eigen::Vector3d delta_g = carried.accel_bias.value_or(Eigen::Vector3d::Zero()) -
                                    now.accel_bias.value_or(Eigen::Vector3d::Zero());
    *s->acc_mps2 += delta_g * kStandardGravity_mps2;
  }
  if (s->gyr_radps && !Same(carried.gyro_bias, now.gyro_bias)) {
    *s->gyr_radps += carried.gyro_bias.value_or(Eigen::Vector3d::Zero()) -
                     now.gyro_bias.value_or(Eigen::Vector3d::Zero());
  }
  const Eigen::Matrix3d identity = Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d s_carried = carried.soft_iron.value_or(identity);
  const Eigen::Matrix3d s_now = now.soft_iron.value_or(identity);
  if (s->mag && (!Same(carried.hard_iron, now.hard_iron) || s_carried != s_now)) {
    const Eigen::Vector3d raw =
        s_carried.inverse() * *s->mag + carried.hard_iron.value_or(Eigen::Vector3d::Zero());
    *s->mag = s_now * (raw - now.hard_iron.value_or(Eigen::Vector3d::Zero()));
  }
}

}  // namespace turncal::sim
