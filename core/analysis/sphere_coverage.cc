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

Eigen::Vector3d CoverageBinCentre(int latitude_bin, int longitude_bin) {
  const double latitude = -M_PI / 2 + (latitude_bin + 0.5) * M_PI / kCoverageLatitudeBins;
  const double longitude = -M_PI + (longitude_bin + 0.5) * 2 * M_PI / kCoverageLongitudeBins;
  return {std::cos(latitude) * std::cos(longitude), std::cos(latitude) * std::sin(longitude),
          std::sin(latitude)};
}

CoverageGap LargestGap(const SphereCoverage& coverage) {
  CoverageGap gap;
  if (coverage.counts.size() != static_cast<std::size_t>(coverage.total) || coverage.filled == 0 ||
      coverage.filled == coverage.total) {
    return gap;
  }
  std::vector<Eigen::Vector3d> filled, empty;
  double empty_area = 0.0, all_area = 0.0;
  for (int la = 0; la < kCoverageLatitudeBins; ++la) {
    // A bin's area is proportional to the sine's difference over its latitude band.
    const double lo = -M_PI / 2 + la * M_PI / kCoverageLatitudeBins;
    const double area = std::sin(lo + M_PI / kCoverageLatitudeBins) - std::sin(lo);
    for (int lo_bin = 0; lo_bin < kCoverageLongitudeBins; ++lo_bin) {
      const bool has =
          coverage.counts[static_cast<std::size_t>(la * kCoverageLongitudeBins + lo_bin)] > 0;
      (has ? filled : empty).push_back(CoverageBinCentre(la, lo_bin));
      all_area += area;
      if (!has) empty_area += area;
    }
  }
  double best_cos = 1.0;  // the largest angle has the smallest cosine to its nearest filled bin
  for (const auto& e : empty) {
    double nearest = -1.0;
    for (const auto& f : filled) nearest = std::max(nearest, e.dot(f));
    if (nearest < best_cos) {
      best_cos = nearest;
      gap.direction = e;
    }
  }
  gap.radius_deg = std::acos(std::clamp(best_cos, -1.0, 1.0)) * 180 / M_PI;
  gap.empty_area_fraction = empty_area / all_area;
  return gap;
}

std::string CaseDirectionName(const Eigen::Vector3d& direction) {
  std::string best;
  double best_cos = -2.0;
  for (int x = -1; x <= 1; ++x) {
    for (int y = -1; y <= 1; ++y) {
      for (int z = -1; z <= 1; ++z) {
        const Eigen::Vector3d c(x, y, z);
        if (c.squaredNorm() == 0) continue;
        const double cosine = c.normalized().dot(direction.normalized());
        if (cosine <= best_cos) continue;
        best_cos = cosine;
        best.clear();
        const int v[3] = {x, y, z};
        for (int k = 0; k < 3; ++k) {
          if (v[k] != 0) best += std::string(v[k] > 0 ? "+" : "-") + static_cast<char>('x' + k);
        }
      }
    }
  }
  return best;
}

std::vector<std::string> CoverageRows(const SphereCoverage& coverage) {
  std::vector<std::string> rows;
  for (int la = kCoverageLatitudeBins - 1; la >= 0; --la) {
    std::string row(kCoverageLongitudeBins, '.');
    for (int lo = 0; lo < kCoverageLongitudeBins; ++lo) {
      const std::size_t k = static_cast<std::size_t>(la * kCoverageLongitudeBins + lo);
      if (k < coverage.counts.size() && coverage.counts[k] > 0) row[lo] = '#';
    }
    rows.push_back(std::move(row));
  }
  return rows;
}

}  // namespace turncal
