#pragma once
// Angle unit factors shared by every layer: multiply degrees by kRadPerDeg to get radians, and
// radians by kDegPerRad to get degrees.

#include <cmath>

namespace turncal {

inline constexpr double kRadPerDeg = M_PI / 180.0;
inline constexpr double kDegPerRad = 180.0 / M_PI;

}  // namespace turncal
