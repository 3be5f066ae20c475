#include "core/frames/rotations.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <set>

namespace turncal {
namespace {

// Seed eq. 4, typed from the document entry by entry.
Mat3<double> SeedEq4(double phi, double gamma, double psi) {
  const double cf = std::cos(phi), sf = std::sin(phi), cg = std::cos(gamma), sg = std::sin(gamma),
               cp = std::cos(psi), sp = std::sin(psi);
  Mat3<double> c;
  c << cg * cp, cg * sp, -sg,                                   //
      sg * cp * sf - sp * cf, sg * sp * sf + cp * cf, cg * sf,  //
      sg * cp * cf + sp * sf, sg * sp * cf - cp * sf, cg * cf;
  return c;
}

void ExpectRotation(const Mat3<double>& r) {
  EXPECT_LT((r * r.transpose() - Mat3<double>::Identity()).cwiseAbs().maxCoeff(), 1e-14);
  EXPECT_NEAR(r.determinant(), 1.0, 1e-14);
}

TEST(Rotations, CpqEqualsSeedEquation4EntryByEntryAtRandomAngles) {
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> angle(-M_PI, M_PI);
  for (int trial = 0; trial < 200; ++trial) {
    const double phi = angle(rng), gamma = angle(rng) / 2, psi = angle(rng);
    const Mat3<double> ours = C_p_q(phi, gamma, psi);
    const Mat3<double> seed = SeedEq4(phi, gamma, psi);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(ours(r, c), seed(r, c), 1e-15) << r << "," << c;
  }
}

TEST(Rotations, EveryRotationIsOrthonormalWithDeterminantOne) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> angle(-M_PI, M_PI);
  for (int trial = 0; trial < 100; ++trial) {
    const double a = angle(rng), b = angle(rng), c = angle(rng);
    ExpectRotation(R1(a));
    ExpectRotation(R2(a));
    ExpectRotation(R3(a));
    ExpectRotation(C_p_q(a, b, c));
    ExpectRotation(C_ned_p(a));
    ExpectRotation(C_q_r(a, b, c));
    ExpectRotation(C_q_r(a, b, c, AxisAlignedRotations()[trial % 24]));
  }
}

TEST(Rotations, ElementaryRotationsArePassiveFrameRotations) {
  // Turning the frame by +90 deg about z makes the old x axis appear at -y.
  const Eigen::Vector3d x(1, 0, 0);
  EXPECT_LT((R3(M_PI / 2) * x - Eigen::Vector3d(0, -1, 0)).norm(), 1e-15);
  EXPECT_LT((R1(M_PI / 2) * Eigen::Vector3d(0, 1, 0) - Eigen::Vector3d(0, 0, -1)).norm(), 1e-15);
  EXPECT_LT((R2(M_PI / 2) * Eigen::Vector3d(0, 0, 1) - Eigen::Vector3d(-1, 0, 0)).norm(), 1e-15);
}

TEST(Rotations, DeterminantOfTrsIsCosAlpha1CosAlpha2SinAlpha3) {
  std::mt19937 rng(6);
  std::uniform_real_distribution<double> angle(-M_PI, M_PI);
  for (int trial = 0; trial < 100; ++trial) {
    const double a1 = angle(rng), a2 = angle(rng), a3 = angle(rng);
    EXPECT_NEAR(T_r_s(a1, a2, a3).determinant(), std::cos(a1) * std::cos(a2) * std::sin(a3), 1e-14);
  }
  EXPECT_LT((T_r_s(0.0, 0.0, M_PI / 2) - Mat3<double>::Identity()).norm(), 1e-15);
}

TEST(Rotations, RowsOfTrsAreUnitSensitiveAxes) {
  const Mat3<double> t = T_r_s(0.01, -0.02, 1.5);
  for (int r = 0; r < 3; ++r) EXPECT_NEAR(t.row(r).norm(), 1.0, 1e-15);
}

TEST(Rotations, TwentyFourDistinctAxisAlignedRotations) {
  std::set<std::vector<double>> seen;
  for (const auto& r : AxisAlignedRotations()) {
    ExpectRotation(r);
    seen.insert(std::vector<double>(r.data(), r.data() + 9));
  }
  EXPECT_EQ(seen.size(), 24u);
}

TEST(Rotations, NearestAxisAlignedRotationUndoesASmallError) {
  for (const auto& m : AxisAlignedRotations()) {
    const Mat3<double> perturbed = C_eps(0.1, -0.2, 0.15) * m;
    EXPECT_EQ(NearestAxisAlignedRotation(perturbed), m);
  }
}

}  // namespace
}  // namespace turncal
