#pragma once
// A 3-vector as a JSON array [x, y, z], both ways (records, noise profiles, calibrations).

#include <Eigen/Core>
#include <nlohmann/json.hpp>

namespace turncal::protocol {

inline nlohmann::json JsonVec3(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

// False unless `j` is an array of three finite numbers.
inline bool ReadJsonVec3(const nlohmann::json& j, Eigen::Vector3d* v) {
  if (!j.is_array() || j.size() != 3) return false;
  for (std::size_t i = 0; i < 3; ++i) {
    if (!j[i].is_number()) return false;
    (*v)[static_cast<Eigen::Index>(i)] = j[i].get<double>();
  }
  return v->allFinite();
}

}  // namespace turncal::protocol
