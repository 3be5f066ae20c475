#include "drivers/mip/mip_stored.h"

#include <Eigen/LU>

#include "core/frames/reference.h"

namespace turncal::drivers::mip {

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

nlohmann::json StoredCalibrationJson(const StoredCalibration& s, bool nulls) {
  Json j = Json::object();
  const auto put = [&](const char* key, const std::optional<Eigen::Vector3d>& v) {
    if (v) {
      j[key] = VectorJson(*v);
    } else if (nulls) {
      j[key] = nullptr;
    }
  };
  put("accel_bias_g", s.accel_bias);
  put("gyro_bias_radps", s.gyro_bias);
  put("hard_iron_gauss", s.hard_iron);
  if (s.soft_iron) {
    j["soft_iron"] = Json::array();
    for (int r = 0; r < 3; ++r) j["soft_iron"].push_back(VectorJson(s.soft_iron->row(r)));
  } else if (nulls) {
    j["soft_iron"] = nullptr;
  }
  return j;
}

bool ParseStoredCalibration(const nlohmann::json& j, StoredCalibration* out, std::string* error) {
  if (!j.is_object()) {
    *error = "a stored calibration is a JSON object";
    return false;
  }
  StoredCalibration read;
  for (const auto& [key, value] :
       {std::pair{"accel_bias_g", &read.accel_bias}, std::pair{"gyro_bias_radps", &read.gyro_bias},
        std::pair{"hard_iron_gauss", &read.hard_iron}}) {
    if (!j.contains(key) || j[key].is_null()) continue;
    Eigen::Vector3d v;
    if (!ReadVector(j[key], &v)) {
      *error = std::string(key) + ": a stored value is not 3 (or 3 x 3) finite numbers";
      return false;
    }
    *value = v;
  }
  if (j.contains("soft_iron") && !j["soft_iron"].is_null()) {
    Eigen::Matrix3d m;
    if (!ReadMatrix(j["soft_iron"], &m)) {
      *error = "soft_iron: a stored value is not 3 (or 3 x 3) finite numbers";
      return false;
    }
    read.soft_iron = m;
  }
  *out = read;
  return true;
}

void ReexpressMipOutput(const StoredCalibration& applied, const StoredCalibration& as_if,
                        Sample* s) {
  if (s->acc_mps2 && !Same(applied.accel_bias, as_if.accel_bias)) {
    const Eigen::Vector3d delta_g = applied.accel_bias.value_or(Eigen::Vector3d::Zero()) -
                                    as_if.accel_bias.value_or(Eigen::Vector3d::Zero());
    *s->acc_mps2 += delta_g * kStandardGravity_mps2;
  }
  if (s->gyr_radps && !Same(applied.gyro_bias, as_if.gyro_bias)) {
    *s->gyr_radps += applied.gyro_bias.value_or(Eigen::Vector3d::Zero()) -
                     as_if.gyro_bias.value_or(Eigen::Vector3d::Zero());
  }
  const Eigen::Matrix3d identity = Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d s_applied = applied.soft_iron.value_or(identity);
  const Eigen::Matrix3d s_as_if = as_if.soft_iron.value_or(identity);
  if (s->mag && (!Same(applied.hard_iron, as_if.hard_iron) || s_applied != s_as_if)) {
    const Eigen::Vector3d raw =
        s_applied.inverse() * *s->mag + applied.hard_iron.value_or(Eigen::Vector3d::Zero());
    *s->mag = s_as_if * (raw - as_if.hard_iron.value_or(Eigen::Vector3d::Zero()));
  }
}

}  // namespace turncal::drivers::mip
