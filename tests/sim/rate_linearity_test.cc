// Issue 21, "several rates expose non-linearity": the rate segments' apparent scale error against
// the rate (core/analysis/rate_linearity.h) on simulated sessions -- a linear gyro's slope is zero
// within its sigma, honestly over sessions; a gyro whose scale grows with the rate
// (SessionSimOptions::gyr_scale_nonlinearity) shows its slope within 4 sigma and is called
// non-linear.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "core/analysis/rate_linearity.h"
#include "core/estimation/calibrator.h"
#include "core/frames/units.h"
#include "sim/session_sim.h"

namespace turncal {
namespace {

RateLinearity Simulated(std::uint64_t seed, double nonlinearity_per_radps) {
  std::string error;
  auto accel = MakeModel("accel13", ModelContext{}, &error);
  auto mag = MakeModel("mag13", ModelContext{}, &error);
  auto gyro = MakeModel("gyro12", ModelContext{}, &error);
  std::vector<TablePose> poses = DefaultSessionPoses();
  poses.resize(12);
  for (const auto& p : DefaultRateSegments()) poses.push_back(p);  // +-100 and +-33.3 deg/s
  SessionSimOptions o;
  o.rate_hz = 100;
  o.seed = seed;
  o.gyr_scale_nonlinearity = nonlinearity_per_radps;
  const SimulatedSession session = SimulateSession(*accel, *mag, poses, o, gyro.get());
  Calibrator calibrator(DriftOptionsForClass(*gyro, o.sensor));
  for (const auto& e : session.events) {
    EXPECT_TRUE(calibrator.add_pose(DwellRecord(session, e, SensorKind::kGyroscope), &error))
        << error;
  }
  const Estimate estimate = calibrator.solve();
  EXPECT_TRUE(estimate.ok) << estimate.error;
  return AnalyzeRateLinearity(*gyro, estimate.theta, calibrator.weighted_poses());
}

TEST(RateLinearity, ALinearGyroShowsNoSlopeAndItsSigmaIsHonest) {
  // 20 sessions: the slope's z has |mean| < 4 / sqrt(20) and a std within [0.6, 1.4].
  const int runs = 20;
  double sum = 0, sum2 = 0;
  for (int run = 0; run < runs; ++run) {
    const RateLinearity r = Simulated(200 + static_cast<std::uint64_t>(run), 0.0);
    ASSERT_TRUE(r.compared);
    ASSERT_EQ(r.levels.size(), 2u);
    EXPECT_NEAR(r.levels[0].rate_dps, 33.3, 0.05);
    EXPECT_NEAR(r.levels[1].rate_dps, 100.0, 1e-9);
    EXPECT_EQ(r.segments, static_cast<int>(DefaultRateSegments().size()));
    EXPECT_TRUE(r.has_asymmetry);
    const double z = r.slope_per_dps / r.slope_sigma;
    if (std::getenv("TURNCAL_PRINT_Z")) {
      std::printf("slope %+.3f ppm/(deg/s) +- %.3f, z %+.2f, chi2 %.2f, p %.3f, asym %+.1f ppm\n",
                  r.slope_per_dps * 1e6, r.slope_sigma * 1e6, z, r.chi2, r.p_value,
                  r.asymmetry * 1e6);
    }
    sum += z;
    sum2 += z * z;
  }
  const double mean = sum / runs, sd = std::sqrt(sum2 / runs - mean * mean);
  EXPECT_LT(std::abs(mean), 4 / std::sqrt(runs));
  EXPECT_GT(sd, 0.6);
  EXPECT_LT(sd, 1.4);
}

TEST(RateLinearity, AScaleThatGrowsWithTheRateIsFoundAndMeasured) {
  // 7.5 ppm per deg/s: 500 ppm between 33.3 and 100 deg/s (industrial sigma ~ 40 ppm).
  const double ppm_per_dps = 7.5;
  const RateLinearity r = Simulated(7, ppm_per_dps * 1e-6 * kDegPerRad);
  ASSERT_TRUE(r.compared);
  EXPECT_LT(std::abs(r.slope_per_dps - ppm_per_dps * 1e-6), 4 * r.slope_sigma)
      << r.slope_per_dps * 1e6 << " +- " << r.slope_sigma * 1e6;
  EXPECT_GT(r.slope_per_dps / r.slope_sigma, 5.0);
  if (std::getenv("TURNCAL_PRINT_Z")) {
    std::printf("non-linear: slope %.3f +- %.3f ppm/(deg/s), %s\n", r.slope_per_dps * 1e6,
                r.slope_sigma * 1e6, r.finding.c_str());
  }
  EXPECT_LT(r.p_value, 1e-3);
  EXPECT_NE(r.finding.find("non-linear"), std::string::npos) << r.finding;
  // The slow segments read below the fast ones by the same amount.
  EXPECT_LT(r.levels[0].scale_error, r.levels[1].scale_error);
}

TEST(RateLinearity, OneRateOrNoneSaysWhatIsMissing) {
  std::string error;
  auto gyro = MakeModel("gyro12", ModelContext{}, &error);
  const RateLinearity none = AnalyzeRateLinearity(*gyro, gyro->nominal(), {});
  EXPECT_EQ(none.segments, 0);
  EXPECT_FALSE(none.compared);
  TablePose spin;
  spin.rate_axis = TableAxis::kInner;
  spin.rate_radps = 1.0;
  WeightedPose w;
  w.pose = spin;
  w.measured = gyro->Predict(gyro->nominal(), spin);
  w.sqrt_information = Eigen::Matrix3d::Identity() * 1e4;
  const RateLinearity one = AnalyzeRateLinearity(*gyro, gyro->nominal(), {w, w});
  EXPECT_EQ(one.segments, 2);
  EXPECT_FALSE(one.compared);
  EXPECT_NE(one.finding.find("a second rate"), std::string::npos) << one.finding;
  // Not a gyroscope: nothing.
  auto accel = MakeModel("accel13", ModelContext{}, &error);
  EXPECT_EQ(AnalyzeRateLinearity(*accel, accel->nominal(), {w}).segments, 0);
}

}  // namespace
}  // namespace turncal
