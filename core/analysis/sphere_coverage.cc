#include "core/analysis/sphere_coverage.h"

#include <algorithm>
#include <cmath>

namespace turncal {

bool CoverageBin(const Eigen::Vector3d& direction, int* latitude_bin, int* longitude_bin) {
  const double n = direction.norm();
  if (!std::isfinite(n) || !(n > 0)) return false;
  const Eigen::Vector3d u = direction / n;
  const double latitude = std::asin(std::clamp(u.z(), -1.0, 1.0));  // [-pi/2, pi/2]
  const double longitude = std::atan2(u.y(), u.x());                // (-pi, pi]
  *latitude_bin =
      std::clamp(static_cast<int>(std::floor((latitude + M_PI / 2) / M_PI * kCoverageLatitudeBins)),
                 0, kCoverageLatitudeBins - 1);
  *longitude_bin = std::clamp(
      static_cast<int>(std::floor((longitude + M_PI) / (2 * M_PI) * kCoverageLongitudeBins)), 0,
      kCoverageLongitudeBins - 1);
  return true;
}

SphereCoverage CoverageOf(const std::vector<Eigen::Vector3d>& directions) {
  SphereCoverage c;
  c.counts.assign(static_cast<std::size_t>(c.total), 0);
  for (const auto& d : directions) {
    int lat = 0, lon = 0;
    if (!CoverageBin(d, &lat, &lon)) continue;
    ++c.directions;
    int& bin = c.counts[static_cast<std::size_t>(lat * kCoverageLongitudeBins + lon)];
    if (bin++ == 0) ++c.filled;
  }
  return c;
}

}  // namespace turncal
