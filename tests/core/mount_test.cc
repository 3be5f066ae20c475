#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/analysis/mount_check.h"
#include "core/frames/mount.h"
#include "core/frames/reference.h"

namespace turncal {
namespace {

constexpr double kDeg = M_PI / 180.0;

TEST(Mount, AxesNameTheCaseAxesInTheTablesFrame) {
  Mat3<double> m;
  ASSERT_TRUE(ParseMountAxes("+x+y+z", &m, nullptr));
  EXPECT_TRUE(m.isApprox(Mat3<double>::Identity()));
  // Case x along the table's -y, case y along +x: rows are the case axes in q.
  ASSERT_TRUE(ParseMountAxes("-y+x+z", &m, nullptr));
  EXPECT_TRUE(m.isApprox(R3(-90.0 * kDeg))) << m;
  // Every one of the 24 round-trips through its name.
  for (const auto& r : AxisAlignedRotations()) {
    const auto name = MountAxesName(r);
    ASSERT_TRUE(name.has_value());
    Mat3<double> back;
    ASSERT_TRUE(ParseMountAxes(*name, &back, nullptr)) << *name;
    EXPECT_TRUE(back.isApprox(r)) << *name;
  }
}

TEST(Mount, AxesThatAreNoRotationAreRefusedWithTheReason) {
  Mat3<double> m;
  std::string error;
  EXPECT_FALSE(ParseMountAxes("-y-x+z", &m, &error));
  EXPECT_NE(error.find("left-handed"), std::string::npos) << error;
  EXPECT_FALSE(ParseMountAxes("+x+x+z", &m, &error));
  EXPECT_NE(error.find("named twice"), std::string::npos) << error;
  EXPECT_FALSE(ParseMountAxes("+x+y+w", &m, &error));
  EXPECT_NE(error.find("'+w'"), std::string::npos) << error;
  EXPECT_FALSE(ParseMountAxes("xyz", &m, &error));
  EXPECT_FALSE(ParseMountAxes("", &m, &error));
}

TEST(Mount, AnglesRoundTripAndNameOnlyAxisAlignedMounts) {
  const Mat3<double> m = MountFromAnglesDeg(10, -20, 45);
  EXPECT_TRUE(MountAnglesDeg(m).isApprox(Eigen::Vector3d(10, -20, 45), 1e-12));
  EXPECT_FALSE(MountAxesName(m).has_value());
  EXPECT_EQ(MountConfigText(m), "[10.000, -20.000, 45.000]");
  EXPECT_EQ(MountConfigText(MountFromAnglesDeg(0, 0, -90)), "\"-y+x+z\"");
  EXPECT_EQ(MountConfigText(MountFromAnglesDeg(180, 0, 0)), "\"+x-y-z\"");
}

TEST(Mount, ARotationIsSaidAboutTheConfiguredCasesAxis) {
  // The observed case is the configured one turned +90 deg about its z (a frame rotation R3).
  EXPECT_EQ(DescribeMountRotation(R3(90.0 * kDeg)), "rotated 90 deg about its +z");
  EXPECT_EQ(DescribeMountRotation(R3(-90.0 * kDeg)), "rotated 90 deg about its -z");
  EXPECT_EQ(DescribeMountRotation(R1(M_PI)), "rotated 180 deg about its +x (upside down)");
  EXPECT_EQ(DescribeMountRotation(R3(M_PI)), "rotated 180 deg about its +z");
  // The cyclic permutation x -> y -> z: 120 deg about the body diagonal.
  Mat3<double> cyc;
  cyc << 0, 1, 0, 0, 0, 1, 1, 0, 0;
  EXPECT_NE(DescribeMountRotation(cyc).find("120 deg about its (+x+y+z)"), std::string::npos)
      << DescribeMountRotation(cyc);
  EXPECT_EQ(DescribeMountRotation(Mat3<double>::Identity()), "as configured");
}

// Poses of a cube (gravity along each table axis, then two tilted), the unit actually at
// `actual`, configured at `configured`, with a mounting error of `eps_deg` and noise.
std::vector<MountObservation> CubeObservations(const Mat3<double>& configured,
                                               const Mat3<double>& actual, double eps_deg,
                                               int poses, std::mt19937* rng) {
  const ReferenceVectors ref;
  const double angles[][2] = {{0, 0}, {90, 0}, {180, 0}, {-90, 0}, {0, 90}, {0, -90}, {45, 30}};
  std::normal_distribution<double> n(0.0, 1.0);
  const Mat3<double> eps = C_eps(eps_deg * kDeg, -eps_deg * kDeg, 0.5 * eps_deg * kDeg);
  std::vector<MountObservation> out;
  for (int k = 0; k < poses; ++k) {
    const Mat3<double> cpq = C_p_q(angles[k % 7][0] * kDeg, angles[k % 7][1] * kDeg, 0.0);
    MountObservation o;
    o.predicted_case = PredictedGravityDirection(configured, cpq, ref.g_ned);
    // Scale 1 %, bias 0.05 m/s^2, noise 0.01 m/s^2: an accelerometer's mean.
    const Eigen::Vector3d f = eps * actual * cpq * (-ref.g_ned);
    o.measured = 1.01 * f + Eigen::Vector3d(0.05, -0.03, 0.02) +
                 0.01 * Eigen::Vector3d(n(*rng), n(*rng), n(*rng));
    out.push_back(o);
  }
  return out;
}

TEST(MountCheck, AUnitInItsSlotPassesWithItsMountingErrorAsMisfit) {
  std::mt19937 rng(3);
  const Mat3<double> m = MountFromAnglesDeg(0, 0, -90);
  for (int poses = 1; poses <= 7; ++poses) {
    const MountCheck c = CheckMount(CubeObservations(m, m, 0.5, poses, &rng));
    EXPECT_FALSE(c.wrong) << poses;
    EXPECT_EQ(c.poses, poses);
    EXPECT_EQ(c.determined, poses >= 2) << poses;
    if (c.determined) {
      EXPECT_TRUE(c.snapped);
      EXPECT_DOUBLE_EQ(c.angle_deg, 0.0);
      EXPECT_LT(c.misfit_deg, 2.0);
    }
  }
}

TEST(MountCheck, EveryWrongAxisAlignedSlotIsFoundFromTwoDirections) {
  std::mt19937 rng(5);
  const Mat3<double> configured = Mat3<double>::Identity();
  int found = 0;
  for (const auto& d : AxisAlignedRotations()) {
    // The unit sits rotated by D in its case frame: actual = D configured.
    const Mat3<double> actual = d * configured;
    const MountCheck c = CheckMount(CubeObservations(configured, actual, 0.5, 2, &rng));
    ASSERT_TRUE(c.determined);
    EXPECT_TRUE(c.rotation.isApprox(d)) << DescribeMountRotation(d);
    EXPECT_EQ(c.wrong, !d.isIdentity()) << DescribeMountRotation(d);
    found += c.wrong;
  }
  EXPECT_EQ(found, 23);
}

TEST(MountCheck, OneDirectionSaysWrongWhenItIsOffButNotWhichRotation) {
  std::mt19937 rng(7);
  const Mat3<double> configured = Mat3<double>::Identity();
  // Upside down: gravity flips at the first pose.
  MountCheck c = CheckMount(CubeObservations(configured, R1(M_PI), 0.5, 1, &rng));
  EXPECT_TRUE(c.wrong);
  EXPECT_FALSE(c.determined);
  EXPECT_GT(c.largest_off_deg, 170.0);
  // Turned 90 deg about z: the first pose (gravity along z) cannot see it, the second can.
  c = CheckMount(CubeObservations(configured, R3(M_PI / 2), 0.5, 1, &rng));
  EXPECT_FALSE(c.wrong);
  c = CheckMount(CubeObservations(configured, R3(M_PI / 2), 0.5, 2, &rng));
  EXPECT_TRUE(c.wrong);
  EXPECT_EQ(DescribeMountRotation(c.rotation), "rotated 90 deg about its +z");
}

TEST(MountCheck, ASlotThatIsNotAxisAlignedIsCheckedInItsOwnFrame) {
  std::mt19937 rng(9);
  const Mat3<double> wedge = MountFromAnglesDeg(0, 30, 45);
  MountCheck c = CheckMount(CubeObservations(wedge, wedge, 0.3, 7, &rng));
  EXPECT_FALSE(c.wrong);
  c = CheckMount(CubeObservations(wedge, R3(M_PI) * wedge, 0.3, 7, &rng));
  EXPECT_TRUE(c.wrong);
  EXPECT_TRUE(c.snapped);
  EXPECT_NEAR(c.angle_deg, 180.0, 1e-9);
}

}  // namespace
}  // namespace turncal
