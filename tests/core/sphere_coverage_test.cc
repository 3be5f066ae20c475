// The spatial coverage of a tumble (core/analysis/sphere_coverage.h, issue 22): 18 x 32
// latitude-longitude bins, as MicroStrain's tool counts them.

#include "core/analysis/sphere_coverage.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace turncal {
namespace {

TEST(SphereCoverage, BinsFollowLatitudeAndLongitude) {
  int lat = -1, lon = -1;
  ASSERT_TRUE(CoverageBin(Eigen::Vector3d(0, 0, 5), &lat, &lon));  // the north pole
  EXPECT_EQ(lat, 17);
  ASSERT_TRUE(CoverageBin(Eigen::Vector3d(0, 0, -1), &lat, &lon));  // the south pole
  EXPECT_EQ(lat, 0);
  ASSERT_TRUE(CoverageBin(Eigen::Vector3d(1, 0, 0), &lat, &lon));  // +x: latitude 0, longitude 0
  EXPECT_EQ(lat, 9);
  EXPECT_EQ(lon, 16);
  ASSERT_TRUE(CoverageBin(Eigen::Vector3d(-1, -1e-9, 0), &lat, &lon));  // just past -180
  EXPECT_EQ(lon, 0);
  ASSERT_TRUE(CoverageBin(Eigen::Vector3d(0, 1, std::tan(25 * M_PI / 180)), &lat, &lon));
  EXPECT_EQ(lat, 11);  // 25 deg north: the bin [20, 30)
  EXPECT_EQ(lon, 24);  // +90 deg: the bin [90, 101.25)
  EXPECT_FALSE(CoverageBin(Eigen::Vector3d::Zero(), &lat, &lon));
  EXPECT_FALSE(CoverageBin(Eigen::Vector3d(NAN, 0, 1), &lat, &lon));
}

TEST(SphereCoverage, SixPositionsFillSixBinsAndAUniformTumbleFillsNearlyAll) {
  const std::vector<Eigen::Vector3d> six = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                                            {0, -1, 0}, {0, 0, 1},  {0, 0, -1}};
  const SphereCoverage c6 = CoverageOf(six);
  EXPECT_EQ(c6.filled, 6);
  EXPECT_EQ(c6.total, 576);
  EXPECT_NEAR(c6.fraction(), 6.0 / 576, 1e-15);
  // 20 000 directions uniform on the sphere: each bin's expected count is 20 000 times its area
  // share; the smallest bins (at the poles, share 2 pi (1 - cos 10 deg) / 32 / 4 pi = 2.4e-4)
  // expect 4.7, so all but a few of 576 are filled: P(empty) = e^-4.7 = 0.9 % for each of 64.
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n;
  std::vector<Eigen::Vector3d> uniform;
  for (int i = 0; i < 20000; ++i) uniform.emplace_back(n(rng), n(rng), n(rng));
  const SphereCoverage cu = CoverageOf(uniform);
  EXPECT_EQ(cu.directions, 20000);
  EXPECT_GE(cu.filled, 570);
  // A tumble about one axis only (directions in the x-y plane) fills one row of bins: 32 of 576.
  std::vector<Eigen::Vector3d> ring;
  for (int i = 0; i < 1000; ++i) {
    const double a = 2 * M_PI * i / 1000;
    ring.emplace_back(std::cos(a), std::sin(a), 0.0);
  }
  const SphereCoverage cr = CoverageOf(ring);
  EXPECT_EQ(cr.filled, 32);  // latitude 0 falls in the bin [0, 10)
  int sum = 0;
  for (int v : cr.counts) sum += v;
  EXPECT_EQ(sum, 1000);
}

// The largest region without a direction: for a hand that only ever turned the upper half (+z
// within 80 degrees of the field) the empty cap is about -z, 90 degrees from the nearest filled bin
// centre (the south pole bin's centre at -85 degrees to the band at +5); half of the sphere's
// area is empty. The rows draw it: the top 9 filled, the bottom 9 empty.
TEST(SphereCoverage, TheLargestGapIsNamedInTheCaseDirections) {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> n;
  std::vector<Eigen::Vector3d> upper;
  for (int i = 0; i < 20000; ++i) {
    Eigen::Vector3d d(n(rng), n(rng), n(rng));
    d.z() = std::abs(d.z());
    upper.push_back(d);
  }
  const SphereCoverage c = CoverageOf(upper);
  const CoverageGap gap = LargestGap(c);
  ASSERT_FALSE(gap.empty());
  EXPECT_EQ(CaseDirectionName(gap.direction), "-z");
  EXPECT_LT(gap.direction.z(), -0.99);
  EXPECT_NEAR(gap.radius_deg, 90.0, 0.5);
  EXPECT_NEAR(gap.empty_area_fraction, 0.5, 0.01);
  const auto rows = CoverageRows(c);
  ASSERT_EQ(rows.size(), 18u);
  EXPECT_EQ(rows[0].size(), 32u);
  EXPECT_EQ(rows[17], std::string(32, '.'));
  EXPECT_EQ(std::count(rows[8].begin(), rows[8].end(), '#'), 32);
  // The ring about z: the caps about both poles are empty, the south's 90 degrees from the band.
  std::vector<Eigen::Vector3d> ring;
  for (int i = 0; i < 1000; ++i) {
    ring.emplace_back(std::cos(2 * M_PI * i / 1000), std::sin(2 * M_PI * i / 1000), 0.0);
  }
  const CoverageGap ring_gap = LargestGap(CoverageOf(ring));
  EXPECT_NEAR(ring_gap.radius_deg, 90.0, 0.5);  // the band is [0, 10): centre +5 to -85
  EXPECT_EQ(CaseDirectionName(ring_gap.direction), "-z");
  EXPECT_NEAR(ring_gap.empty_area_fraction, 1.0 - (std::sin(10 * M_PI / 180)) / 2, 1e-9);
  // Nothing and everything have no gap; edges and corners have their names.
  EXPECT_TRUE(LargestGap(CoverageOf({})).empty());
  EXPECT_EQ(CaseDirectionName({1, 1, 0.1}), "+x+y");
  EXPECT_EQ(CaseDirectionName({-1, 1, -1}), "-x+y-z");
}

}  // namespace
}  // namespace turncal
