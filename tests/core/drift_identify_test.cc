// Identifying the drift's strength from the poses (core/estimation/drift_identify.h): restricted
// likelihood of the residuals with the configured drift as the prior.
#include "core/estimation/drift_identify.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <random>

#include "core/estimation/calibrator.h"
#include "sim/session_sim.h"
#include "sim/synthetic.h"

namespace turncal {
namespace {

// n poses 9 s apart (5 s windows), a random 3n x N design with the bias in its last three columns,
// and errors drawn from the drift (stationary Gauss-Markov of `true_sigma`) plus white noise.
struct Session {
  Eigen::MatrixXd J;
  Eigen::VectorXd e;
  std::vector<Eigen::Vector3d> white;
  std::vector<TimeWindow> windows;
};

Session Draw(int n, double true_sigma, double white_var, std::mt19937_64* rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  const int N = 9;
  Session s;
  s.J.resize(3 * n, N);
  for (int i = 0; i < 3 * n; ++i)
    for (int j = 0; j < N - 3; ++j) s.J(i, j) = normal(*rng);
  s.J.rightCols(3).setZero();
  for (int i = 0; i < n; ++i) {
    s.J.block<3, 3>(3 * i, N - 3).setIdentity();
    s.windows.push_back({9.0 * i, 9.0 * i + 5});
    s.white.push_back(Eigen::Vector3d::Constant(white_var));
  }
  BiasDrift truth;
  truth.gm_sigma.setConstant(true_sigma);
  truth.gm_tau_s = 100;
  s.e.resize(3 * n);
  for (int a = 0; a < 3; ++a) {
    Eigen::MatrixXd K(n, n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j)
        K(i, j) = truth.WindowCovariance(a, s.windows[i], s.windows[j], 0);
    K.diagonal().array() += white_var;
    const Eigen::MatrixXd L = K.llt().matrixL();
    Eigen::VectorXd z(n);
    for (int i = 0; i < n; ++i) z[i] = normal(*rng);
    const Eigen::VectorXd x = L * z;
    for (int i = 0; i < n; ++i) s.e[3 * i + a] = x[i];
  }
  return s;
}

BiasDrift Prior() {
  BiasDrift d;
  d.gm_sigma.setConstant(4e-4);
  d.gm_tau_s = 100;
  return d;
}

TEST(DriftIdentify, FindsADriftThreeTimesThePriorWithinItsSigma) {
  std::mt19937_64 rng(11);
  int within = 0;
  const int reps = 40;
  for (int k = 0; k < reps; ++k) {
    const Session s = Draw(60, 3 * 4e-4, 1e-8, &rng);
    const DriftScale d = IdentifyDriftScale(s.J, s.e, s.white, s.windows, Prior());
    ASSERT_TRUE(d.identified);
    EXPECT_LT(d.log_sigma, d.prior_log_sigma);  // the data say more than the prior
    within += std::abs(std::log(d.scale / 3.0)) <= 2 * d.log_sigma;
  }
  // The posterior pulls towards the prior's 1, so its 2-sigma interval covers 3 a little less
  // often than 95 %; far more often than not all the same.
  EXPECT_GE(within, reps * 3 / 4) << within << " of " << reps;
}

TEST(DriftIdentify, IsUnbiasedWhenThePriorIsRightAndHoldsThePriorWithFewPoses) {
  std::mt19937_64 rng(12);
  double sum = 0, sum2 = 0;
  const int reps = 100;
  for (int k = 0; k < reps; ++k) {
    const Session s = Draw(40, 4e-4, 1e-8, &rng);
    const DriftScale d = IdentifyDriftScale(s.J, s.e, s.white, s.windows, Prior());
    ASSERT_TRUE(d.identified);
    sum += std::log(d.scale);
    sum2 += std::log(d.scale) * std::log(d.scale);
  }
  const double mean = sum / reps, sd = std::sqrt(sum2 / reps - mean * mean);
  // REML (not ML): no downward bias of ln s beyond the sampling of the mean.
  EXPECT_LT(std::abs(mean), 4 * sd / std::sqrt(reps) + 0.02) << mean << " sd " << sd;
  // Four poses (12 equations, 9 parameters) say little: the prior holds s near 1.
  const Session few = Draw(4, 3 * 4e-4, 1e-8, &rng);
  const DriftScale d = IdentifyDriftScale(few.J, few.e, few.white, few.windows, Prior());
  ASSERT_TRUE(d.identified);
  EXPECT_GT(d.data_log_sigma, d.prior_log_sigma);
  EXPECT_LT(std::abs(std::log(d.scale)), 2.5 * d.prior_log_sigma);
}

TEST(DriftIdentify, NothingToIdentifyWithoutADriftModelOrDegreesOfFreedom) {
  std::mt19937_64 rng(13);
  const Session s = Draw(3, 4e-4, 1e-8, &rng);  // 9 equations, 9 parameters
  EXPECT_FALSE(IdentifyDriftScale(s.J, s.e, s.white, s.windows, Prior()).identified);
  const Session t = Draw(10, 4e-4, 1e-8, &rng);
  EXPECT_FALSE(IdentifyDriftScale(t.J, t.e, t.white, t.windows, BiasDrift{}).identified);
}

// Through the calibrator: sessions of the sample-level simulator whose bias wanders three times
// as much as the class says, calibrated with the class's drift as the prior. Identified, the drift
// comes out near 3 and every parameter's z is unit normal; the prior alone is far off (the
// pipeline's version of this: docs/ACCURACY.md "The drift's strength from the session").
TEST(DriftIdentify, TheCalibratorIdentifiesADriftThreeTimesTheClasssAndStaysHonest) {
  std::string error;
  auto accel = MakeModel("accel13", ModelContext{}, &error);
  auto mag = MakeModel("mag13", ModelContext{}, &error);
  const auto poses = DefaultSessionPoses();
  const int N = accel->num_parameters(), runs = 80;
  Eigen::VectorXd s1 = Eigen::VectorXd::Zero(N), s2 = Eigen::VectorXd::Zero(N);
  double log_scale = 0;
  int rejected = 0;
  for (int run = 0; run < runs; ++run) {
    SessionSimOptions o;
    o.sensor = IndustrialClass();
    o.sensor.acc_bias_instability *= 3;
    o.rate_hz = 50;
    o.seed = 2000 + static_cast<std::uint64_t>(run);
    const SimulatedSession s = SimulateSession(*accel, *mag, poses, o);
    CalibratorOptions options = DriftOptionsForClass(*accel, IndustrialClass());
    options.identify_drift = true;
    Calibrator c(options);
    Estimate est;
    for (const auto& e : s.events) {
      ASSERT_TRUE(c.add_pose(DwellRecord(s, e, SensorKind::kAccelerometer), &error)) << error;
      if (c.num_poses() >= 6) est = c.solve();  // pose by pose, as the station solves
    }
    ASSERT_TRUE(est.ok) << est.error;
    ASSERT_TRUE(est.drift_scale.identified);
    rejected += est.drift_scale.rejects_prior;
    log_scale += std::log(est.drift_scale_used);
    Eigen::VectorXd truth = s.accel_truth;
    truth.tail<3>() += s.LastPoseAccBiasOffset();
    const Eigen::VectorXd z = (est.theta - truth).cwiseQuotient(est.sigma);
    s1 += z;
    s2 += z.cwiseAbs2();
  }
  EXPECT_GE(rejected, runs * 9 / 10);
  EXPECT_NEAR(log_scale / runs, std::log(3.0), 0.15);
  // 80 sessions: std z scatters by 1/sqrt(160) = 0.079; [0.75, 1.25] is a 3.2 sigma window.
  const Eigen::VectorXd mean = s1 / runs;
  const Eigen::VectorXd std = (s2 / runs - mean.cwiseAbs2()).cwiseMax(0).cwiseSqrt();
  for (int i = 0; i < N; ++i) {
    EXPECT_GT(std[i], 0.75) << accel->parameters()[i].name;
    EXPECT_LT(std[i], 1.25) << accel->parameters()[i].name;
    EXPECT_LT(std::abs(mean[i]), 0.35) << accel->parameters()[i].name;
  }
}

}  // namespace
}  // namespace turncal
