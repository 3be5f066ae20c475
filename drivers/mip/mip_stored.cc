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
  const auto put_matrix = [&](const char* key, const std::optional<Eigen::Matrix3d>& m) {
    if (m) {
      j[key] = Json::array();
      for (int r = 0; r < 3; ++r) j[key].push_back(VectorJson(m->row(r)));
    } else if (nulls) {
      j[key] = nullptr;
    }
  };
  put_matrix("soft_iron", s.soft_iron);
  // Only a device that has one: identities that predate the transform keep their shape.
  if (s.transform) put_matrix("sensor_to_vehicle", s.transform);
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
  for (const auto& [key, value] :
       {std::pair{"soft_iron", &read.soft_iron}, std::pair{"sensor_to_vehicle", &read.transform}}) {
    if (!j.contains(key) || j[key].is_null()) continue;
    Eigen::Matrix3d m;
    if (!ReadMatrix(j[key], &m)) {
      *error = std::string(key) + ": a stored value is not 3 (or 3 x 3) finite numbers";
      return false;
    }
    *value = m;
  }
  *out = read;
  return true;
}

Eigen::Matrix3d ReexpressLinear(const StoredCalibration& applied, const StoredCalibration& as_if,
                                bool magnetometer) {
  const Eigen::Matrix3d identity = Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d m_applied = applied.transform.value_or(identity);
  const Eigen::Matrix3d m_as_if = as_if.transform.value_or(identity);
  if (!magnetometer) return m_as_if * m_applied.inverse();
  return m_as_if * as_if.soft_iron.value_or(identity) *
         applied.soft_iron.value_or(identity).inverse() * m_applied.inverse();
}

void ReexpressMipOutput(const StoredCalibration& applied, const StoredCalibration& as_if,
                        Sample* s) {
  const Eigen::Matrix3d identity = Eigen::Matrix3d::Identity();
  const bool same_transform =
      applied.transform.value_or(identity) == as_if.transform.value_or(identity);
  const Eigen::Matrix3d m_applied = applied.transform.value_or(identity);
  const Eigen::Matrix3d m_as_if = as_if.transform.value_or(identity);
  // accel out = M (raw - b) in g; gyro likewise in rad/s.
  const auto bias_triad = [&](std::optional<Eigen::Vector3d>* out,
                              const std::optional<Eigen::Vector3d>& b_applied,
                              const std::optional<Eigen::Vector3d>& b_as_if, double unit) {
    if (!*out || (same_transform && Same(b_applied, b_as_if))) return;
    const Eigen::Vector3d raw =
        m_applied.inverse() * **out + b_applied.value_or(Eigen::Vector3d::Zero()) * unit;
    **out = m_as_if * (raw - b_as_if.value_or(Eigen::Vector3d::Zero()) * unit);
  };
  bias_triad(&s->acc_mps2, applied.accel_bias, as_if.accel_bias, kStandardGravity_mps2);
  bias_triad(&s->gyr_radps, applied.gyro_bias, as_if.gyro_bias, 1.0);
  const Eigen::Matrix3d s_applied = applied.soft_iron.value_or(identity);
  const Eigen::Matrix3d s_as_if = as_if.soft_iron.value_or(identity);
  if (s->mag &&
      (!same_transform || !Same(applied.hard_iron, as_if.hard_iron) || s_applied != s_as_if)) {
    // mag out = M S (raw - h).
    const Eigen::Vector3d raw = (m_applied * s_applied).inverse() * *s->mag +
                                applied.hard_iron.value_or(Eigen::Vector3d::Zero());
    *s->mag = m_as_if * s_as_if * (raw - as_if.hard_iron.value_or(Eigen::Vector3d::Zero()));
  }
}

}  // namespace turncal::drivers::mip
