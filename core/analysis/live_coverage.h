#pragma once
// The magnetometer's coverage as its values arrive (issue 37, live guidance: turncald's COVERAGE
// event, `turncal watch`): each value's direction in MicroStrain's 18 x 32 bins, counted once.
// A direction needs the hard iron taken out: the latest fit's correction once there is one, else
// the midpoint of the values' range on each axis (their 2nd and 98th percentiles, so that a few
// disturbed values do not move it), recounted whenever it changes. Pure computation.

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "core/analysis/sphere_coverage.h"
#include "core/estimation/free_motion.h"

namespace turncal {

class LiveCoverage {
 public:
  // A raw value to its direction (a fit's correction of it).
  using Correction = std::function<Eigen::Vector3d(const Eigen::Vector3d& raw)>;

  // From now on the directions are `correct`'s (what it is: "the magellipsoid fit"); the values
  // are counted again at the next Update.
  void SetCorrection(Correction correct, std::string source);
  // Counts `values` (a MotionCollector's: appended to in time order, thinned to bound memory --
  // `thinned`, its count of values dropped, changing means recount) not yet counted.
  const SphereCoverage& Update(const std::vector<MotionValue>& values, std::int64_t thinned);
  // "the magellipsoid fit", "the values' midpoint (no fit yet)".
  const std::string& source() const { return source_; }

 private:
  void Clear();
  Correction correct_;
  std::string source_ = "the values' midpoint (no fit yet)";
  SphereCoverage coverage_;
  std::size_t counted_ = 0;
  std::int64_t thinned_ = -1;
};

// The midpoint of the values' range on each axis, between their `low` and 1 - `low` quantiles.
Eigen::Vector3d RangeMidpoint(const std::vector<MotionValue>& values, double low = 0.02);

}  // namespace turncal
