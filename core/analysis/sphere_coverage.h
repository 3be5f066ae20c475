#pragma once
// How much of the sphere of directions a tumble covered (issue 22, observability for a tumble):
// the share of 18 x 32 latitude-longitude bins (10 degrees of latitude by 11.25 degrees of
// longitude) that hold at least one direction, as MicroStrain's magnetometer tool defines its
// spatial coverage, so that users can compare the two. Latitude is the angle above the x-y plane
// of the sensor frame, longitude the angle about z from x. The bins are equal in angle, not in
// area: a direction near a pole fills a small bin. Pure computation.

#include <Eigen/Core>
#include <string>
#include <vector>

namespace turncal {

inline constexpr int kCoverageLatitudeBins = 18;
inline constexpr int kCoverageLongitudeBins = 32;

struct SphereCoverage {
  int filled = 0;  // bins holding at least one direction
  int total = kCoverageLatitudeBins * kCoverageLongitudeBins;
  int directions = 0;  // counted (zero vectors and non-finite ones are left out)
  double fraction() const { return static_cast<double>(filled) / total; }
  // Per bin, latitude-major (row = latitude bin from -90 deg up, column = longitude bin from -180).
  std::vector<int> counts;
};

// The coverage of `directions` (any length; only the direction counts).
SphereCoverage CoverageOf(const std::vector<Eigen::Vector3d>& directions);

// The bin of one direction: latitude bin (0..17) and longitude bin (0..31); false for a zero or
// non-finite vector.
bool CoverageBin(const Eigen::Vector3d& direction, int* latitude_bin, int* longitude_bin);

// The unit direction at the centre of a bin.
Eigen::Vector3d CoverageBinCentre(int latitude_bin, int longitude_bin);

// The largest region of the sphere without a direction (issue 37, live guidance): the centre of
// the empty bin farthest from every filled one, how far that is (the radius of the empty cap about
// it, between bin centres) and the share of the sphere's area (not of its bins) that holds no
// direction. Empty (radius 0) when every bin is filled or none is.
struct CoverageGap {
  Eigen::Vector3d direction = Eigen::Vector3d::Zero();  // unit, in the triad's frame
  double radius_deg = 0.0;
  double empty_area_fraction = 0.0;
  bool empty() const { return !(radius_deg > 0); }
};
CoverageGap LargestGap(const SphereCoverage& coverage);

// The nearest of the 26 axis, edge and corner directions of the case, as users name them: "+x",
// "-z", "+x-y", "-x+y+z".
std::string CaseDirectionName(const Eigen::Vector3d& direction);

// The coverage as 18 lines of 32 characters, the north pole's (+z) latitude first: '#' a bin with
// a direction, '.' one without (what turncald's COVERAGE event carries and `turncal watch` draws).
std::vector<std::string> CoverageRows(const SphereCoverage& coverage);

}  // namespace turncal
