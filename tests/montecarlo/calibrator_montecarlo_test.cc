// The calibrator's Monte Carlo (montecarlo/calibrator_montecarlo.h, `turncal montecarlo`): the
// pose designs, and a short run whose z-scores have the spread an honest sigma gives.
#include "montecarlo/calibrator_montecarlo.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/planning/pose_designs.h"

namespace turncal::montecarlo {
namespace {

// The cube design repeats the 26 directions, each repeat turned 45 deg about the outer axis.
TEST(DesignPoses, TheCubeRepeatsTurnedByAnEighthTurn) {
  std::mt19937_64 rng(1);
  const std::vector<TablePose> cube = CubePoses26();
  const std::vector<TablePose> poses = DesignPoses("cube", 30, &rng);
  ASSERT_EQ(poses.size(), 30u);
  for (int i = 0; i < 26; ++i) EXPECT_EQ(poses[i].psi_rad, cube[i].psi_rad);
  for (int i = 26; i < 30; ++i) {
    EXPECT_DOUBLE_EQ(poses[i].psi_rad, cube[i - 26].psi_rad + M_PI / 4);
    EXPECT_EQ(poses[i].phi_rad, cube[i - 26].phi_rad);
  }
  EXPECT_EQ(DesignPoses("about-z", 12, &rng).size(), 12u);
  EXPECT_EQ(DesignPoses("random", 7, &rng).size(), 7u);
}

TEST(CalibratorMonteCarlo, AnUnknownModelIsRefused) {
  CalibratorMonteCarloOptions o;
  o.model = "accel99";
  o.runs = 2;
  const CalibratorMonteCarloSummary s = RunCalibratorMonteCarlo(o);
  EXPECT_NE(s.error.find("accel99"), std::string::npos) << s.error;
  EXPECT_EQ(s.solved, 0);
}

// 150 sessions of accel13 over 40 random poses with white noise (the calibrator's own noise
// model, so its sigma is the Cramer-Rao bound): each parameter's z has mean 0 within 4 /
// sqrt(150) = 0.33 and spread 1 within 4 / sqrt(300) = 0.23, and the RMSE is the mean sigma
// within the same; at most 3 of the 13 x 150 beyond 4 sigma (Poisson of mean 0.12: P ~ 1e-5).
TEST(CalibratorMonteCarlo, ZScoresOfWhiteNoiseSessionsHaveUnitSpread) {
  CalibratorMonteCarloOptions o;
  o.model = "accel13";
  o.poses = 40;
  o.runs = 150;
  o.seed = 5;
  const CalibratorMonteCarloSummary s = RunCalibratorMonteCarlo(o);
  ASSERT_TRUE(s.error.empty()) << s.error;
  EXPECT_EQ(s.solved, 150);
  EXPECT_EQ(s.failed, 0);
  EXPECT_EQ(s.poses, 40);
  ASSERT_EQ(s.parameters.size(), 13u);
  const Eigen::VectorXd mean = s.z.Mean(), std_z = s.z.Std();
  for (int i = 0; i < 13; ++i) {
    EXPECT_NEAR(mean[i], 0.0, 4 / std::sqrt(150.0)) << s.parameters[i];
    EXPECT_NEAR(std_z[i], 1.0, 4 / std::sqrt(300.0)) << s.parameters[i];
    EXPECT_NEAR(s.rmse[i] / s.sigma[i], 1.0, 4 / std::sqrt(300.0)) << s.parameters[i];
  }
  EXPECT_LE(s.z.BeyondFour().sum(), 3);
}

}  // namespace
}  // namespace turncal::montecarlo
