// Issue 21: the session simulator's gyroscope (truth, Earth's rate, rate segments) agrees with the
// gyro models: ideal-cut records of a simulated session calibrate gyro12 and gyro21 to their truth.

#include <gtest/gtest.h>

#include <cmath>

#include "core/estimation/calibrator.h"
#include "sim/session_sim.h"

namespace turncal {
namespace {

struct GyroRun {
  std::unique_ptr<MeasurementModel> accel, mag, gyro;
  SimulatedSession session;
  Estimate estimate;
  Eigen::VectorXd truth;  // with the bias over the latest record's window
};

GyroRun RunSession(const std::string& model, const SensorClass& sensor, std::uint64_t seed,
                   bool with_rates = true) {
  GyroRun r;
  std::string error;
  r.accel = MakeModel("accel13", ModelContext{}, &error);
  r.mag = MakeModel("mag13", ModelContext{}, &error);
  r.gyro = MakeModel(model, ModelContext{}, &error);
  std::vector<TablePose> poses = DefaultSessionPoses();
  if (with_rates) {
    for (const auto& p : DefaultRateSegments()) poses.push_back(p);
  }
  SessionSimOptions o;
  o.sensor = sensor;
  o.rate_hz = 100;
  o.seed = seed;
  r.session = SimulateSession(*r.accel, *r.mag, poses, o, r.gyro.get());
  Calibrator calibrator(DriftOptionsForClass(*r.gyro, sensor));
  for (const auto& e : r.session.events) {
    const PoseRecord record = DwellRecord(r.session, e, SensorKind::kGyroscope);
    EXPECT_TRUE(calibrator.add_pose(record, &error)) << error;
  }
  r.estimate = calibrator.solve();
  r.truth = r.session.gyro_truth;
  const auto& last = r.session.events.back();
  r.truth.segment<3>(r.gyro->index_of("bx")) += last.gyr_wander_mean;
  return r;
}

TEST(GyroSession, RateSegmentsLastWholeRevolutionsAtTheRate) {
  std::string error;
  auto accel = MakeModel("accel13", ModelContext{}, &error);
  auto mag = MakeModel("mag13", ModelContext{}, &error);
  auto gyro = MakeModel("gyro12", ModelContext{}, &error);
  SessionSimOptions o;
  o.rate_hz = 200;
  o.sensor.gyr_noise_density = 0;  // the rate itself
  o.sensor.gyr_bias_instability = 0;
  const auto rates = DefaultRateSegments(90.0, false);
  const SimulatedSession s = SimulateSession(*accel, *mag, rates, o, gyro.get());
  ASSERT_EQ(s.events.size(), rates.size());
  for (const auto& e : s.events) {
    // Whole revolutions, at least dwell_s.
    const double turns = e.revolutions_s * std::abs(e.pose.rate_radps) / (2 * M_PI);
    EXPECT_NEAR(turns, std::round(turns), 1e-9);
    EXPECT_GE(e.revolutions_s, o.dwell_s);
    // The mean output over the window is the model's prediction within the ripple's share.
    const PoseRecord r = DwellRecord(s, e, SensorKind::kGyroscope);
    ASSERT_TRUE(r.gyr);
    const Eigen::Vector3d predicted = gyro->Predict(s.gyro_truth, e.pose);
    EXPECT_LT((r.gyr->mean - predicted).norm(), 3e-4 * std::abs(e.pose.rate_radps))
        << ToString(e.pose.rate_axis) << " " << e.pose.rate_radps;
  }
}

void ExpectWithinFourSigma(const GyroRun& r) {
  const Estimate& e = r.estimate;
  ASSERT_TRUE(e.ok) << e.error;
  for (int i = 0; i < e.theta.size(); ++i) {
    EXPECT_LT(std::abs(e.theta[i] - r.truth[i]) / e.sigma[i], 4.0)
        << e.model << " " << e.parameters[i].name << " est " << e.theta[i] << " truth "
        << r.truth[i] << " sigma " << e.sigma[i];
  }
}

TEST(GyroSession, Gyro12FromStaticPosesAndRateSegments) {
  for (std::uint64_t seed : {1, 2, 3})
    ExpectWithinFourSigma(RunSession("gyro12", IndustrialClass(), seed));
}

TEST(GyroSession, Gyro21ConsumerFromStaticPosesAndRateSegments) {
  for (std::uint64_t seed : {1, 2, 3})
    ExpectWithinFourSigma(RunSession("gyro21", ConsumerClass(), seed));
}

}  // namespace
}  // namespace turncal
