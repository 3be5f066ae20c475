#include "core/frames/reference.h"

#include <cmath>

namespace turncal {

bool ReferenceVectors::IsValid(std::string* error) const {
  auto bad = [&](const char* what) {
    if (error) *error = std::string(what) + " must be finite and non-zero";
    return false;
  };
  if (!g_ned.allFinite() || g_ned.norm() < 1e-9) return bad("g_ned");
  if (!B_ned.allFinite() || B_ned.norm() < 1e-12) return bad("B_ned");
  if (!std::isfinite(latitude_deg) || std::abs(latitude_deg) > 90.0) {
    if (error) *error = "latitude_deg must be a latitude in [-90, 90]";
    return false;
  }
  return true;
}

Eigen::Vector3d EarthRateNed(const ReferenceVectors& ref) {
  const double lat = ref.latitude_deg * M_PI / 180.0;
  return kEarthRate_radps * Eigen::Vector3d(std::cos(lat), 0.0, -std::sin(lat));
}

}  // namespace turncal
