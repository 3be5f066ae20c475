#include "core/analysis/live_coverage.h"

#include <algorithm>
#include <cmath>

namespace turncal {

Eigen::Vector3d RangeMidpoint(const std::vector<MotionValue>& values, double low) {
  Eigen::Vector3d mid = Eigen::Vector3d::Zero();
  if (values.empty()) return mid;
  std::vector<double> axis(values.size());
  const auto n = static_cast<double>(values.size() - 1);
  const auto lo = static_cast<std::ptrdiff_t>(std::floor(low * n));
  const auto hi = static_cast<std::ptrdiff_t>(std::ceil((1 - low) * n));
  for (int k = 0; k < 3; ++k) {
    for (std::size_t i = 0; i < values.size(); ++i) axis[i] = values[i].mag[k];
    std::nth_element(axis.begin(), axis.begin() + lo, axis.end());
    const double a = axis[static_cast<std::size_t>(lo)];
    std::nth_element(axis.begin(), axis.begin() + hi, axis.end());
    mid[k] = 0.5 * (a + axis[static_cast<std::size_t>(hi)]);
  }
  return mid;
}

void LiveCoverage::SetCorrection(Correction correct, std::string source) {
  correct_ = std::move(correct);
  source_ = std::move(source);
  Clear();
}

void LiveCoverage::Clear() {
  coverage_ = SphereCoverage();
  coverage_.counts.assign(static_cast<std::size_t>(coverage_.total), 0);
  counted_ = 0;
}

const SphereCoverage& LiveCoverage::Update(const std::vector<MotionValue>& values,
                                           std::int64_t thinned) {
  // Without a fit the midpoint moves with every value: count them all again about it.
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  if (!correct_) {
    centre = RangeMidpoint(values);
    Clear();
  } else if (thinned != thinned_ || values.size() < counted_ || coverage_.counts.empty()) {
    Clear();
  }
  thinned_ = thinned;
  for (std::size_t i = counted_; i < values.size(); ++i) {
    const Eigen::Vector3d d =
        correct_ ? correct_(values[i].mag) : Eigen::Vector3d(values[i].mag - centre);
    int lat = 0, lon = 0;
    if (!CoverageBin(d, &lat, &lon)) continue;
    ++coverage_.directions;
    int& bin = coverage_.counts[static_cast<std::size_t>(lat * kCoverageLongitudeBins + lon)];
    if (bin++ == 0) ++coverage_.filled;
  }
  counted_ = values.size();
  return coverage_;
}

}  // namespace turncal
