#include "core/modeling/accel_physical.h"

#include <gtest/gtest.h>

#include <random>

namespace turncal {
namespace {

AccelPhysical RandomNearNominal(std::mt19937* rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  AccelPhysical p;
  for (int i = 0; i < 3; ++i) {
    p.S[i] = 5e-3 * n(*rng);
    p.alpha[i] += 2e-3 * n(*rng);
    p.eps[i] = 5e-3 * n(*rng);
  }
  return p;
}

TEST(AccelPhysical, PhysicalToGToPhysicalRoundTripsTo1e12) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 2000; ++trial) {
    const AccelPhysical p = RandomNearNominal(&rng);
    const Mat3<double>& mounting = AxisAlignedRotations()[trial % 24];
    AccelPhysical back;
    std::string error;
    ASSERT_TRUE(AccelPhysicalFromG(AccelGFromPhysical(p, mounting), mounting, &back, &error))
        << error;
    EXPECT_LT((back.S - p.S).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LT((back.alpha - p.alpha).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LT((back.eps - p.eps).cwiseAbs().maxCoeff(), 1e-12);
  }
}

TEST(AccelPhysical, GToPhysicalToGRoundTripsTo1e12) {
  std::mt19937 rng(12);
  std::normal_distribution<double> n(0.0, 1e-2);
  for (int trial = 0; trial < 1000; ++trial) {
    Mat3<double> G = Mat3<double>::Identity();
    for (int i = 0; i < 9; ++i) G.data()[i] += n(rng);
    AccelPhysical p;
    std::string error;
    ASSERT_TRUE(AccelPhysicalFromG(G, Mat3<double>::Identity(), &p, &error)) << error;
    EXPECT_LT((AccelGFromPhysical(p, Mat3<double>::Identity()) - G).cwiseAbs().maxCoeff(), 1e-12);
  }
}

TEST(AccelPhysical, LQHasPositiveDiagonalAndOrthogonalQ) {
  Mat3<double> G;
  G << 0.2, -1.0, 0.1, 0.9, 0.05, 0.3, -0.1, 0.2, -1.1;
  Mat3<double> L, Q;
  DecomposeLQ(G, &L, &Q);
  EXPECT_LT((L * Q - G).norm(), 1e-14);
  EXPECT_LT((Q * Q.transpose() - Mat3<double>::Identity()).norm(), 1e-14);
  for (int i = 0; i < 3; ++i) EXPECT_GT(L(i, i), 0.0);
  EXPECT_NEAR(L(0, 1), 0.0, 1e-15);
  EXPECT_NEAR(L(0, 2), 0.0, 1e-15);
  EXPECT_NEAR(L(1, 2), 0.0, 1e-15);
}

TEST(AccelPhysical, WrongMountingOrSingularGIsAnError) {
  std::string error;
  AccelPhysical p;
  Mat3<double> mirrored = Mat3<double>::Identity();
  mirrored(2, 2) = -1;  // a left-handed "rotation": det G < 0
  EXPECT_FALSE(AccelPhysicalFromG(mirrored, Mat3<double>::Identity(), &p, &error));
  EXPECT_NE(error.find("det G < 0"), std::string::npos) << error;
  EXPECT_FALSE(AccelPhysicalFromG(Mat3<double>::Zero(), Mat3<double>::Identity(), &p, &error));
  EXPECT_NE(error.find("singular"), std::string::npos) << error;
  Mat3<double> nan = Mat3<double>::Identity();
  nan(1, 1) = std::nan("");
  EXPECT_FALSE(AccelPhysicalFromG(nan, Mat3<double>::Identity(), &p, &error));
}

}  // namespace
}  // namespace turncal
