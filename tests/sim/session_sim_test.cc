#include "sim/session_sim.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/estimation/calibrator.h"

namespace turncal {
namespace {

struct SimRun {
  std::unique_ptr<MeasurementModel> accel, mag;
  std::vector<TablePose> poses;
  SimulatedSession session;
};

SimRun Simulate(const SessionSimOptions& o, int n_poses = 36) {
  SimRun r;
  std::string error;
  r.accel = MakeModel("accel13", ModelContext{}, &error);
  r.mag = MakeModel("mag13", ModelContext{}, &error);
  r.poses = DefaultSessionPoses();
  r.poses.resize(static_cast<std::size_t>(n_poses));
  r.session = SimulateSession(*r.accel, *r.mag, r.poses, o);
  return r;
}

TEST(SessionSim, TimelineEventsAndDeterminism) {
  SessionSimOptions o;
  o.rate_hz = 100;
  o.dwell_s = 2;
  const SimRun a = Simulate(o, 5), b = Simulate(o, 5);
  ASSERT_EQ(a.session.events.size(), 5u);
  EXPECT_NEAR(a.session.duration_s, o.start_s + 5 * (o.move_s + o.settle_s + o.dwell_s), 1e-9);
  EXPECT_EQ(a.session.samples.size(), static_cast<std::size_t>(a.session.duration_s * o.rate_hz));
  ASSERT_EQ(a.session.samples.size(), b.session.samples.size());
  for (std::size_t i = 0; i < a.session.samples.size(); i += 97) {
    EXPECT_EQ(*a.session.samples[i].acc_mps2, *b.session.samples[i].acc_mps2);
  }
  // The device clock runs 20 ppm fast from 10 s.
  const auto& last = a.session.samples.back();
  EXPECT_NEAR(*last.t_device_s - 10.0, last.t_host_ns * 1e-9 * (1 + 20e-6), 1e-9);
}

TEST(SessionSim, GyroSeesTheTableMoveAndOnlyItsBiasAtRest) {
  SessionSimOptions o;
  o.rate_hz = 200;
  const SimRun r = Simulate(o, 3);
  const auto& e = r.session.events[1];
  Eigen::Vector3d rest = Eigen::Vector3d::Zero();
  int n = 0;
  double moving_max = 0;
  for (const auto& s : r.session.samples) {
    const double t = s.t_host_ns * 1e-9;
    if (t >= e.t_s && t < e.dwell_end_s) {
      rest += *s.gyr_radps;
      ++n;
    }
    if (t > e.t_s - o.settle_s - o.move_s + 0.5 && t < e.t_s - o.settle_s - 0.5) {
      moving_max = std::max(moving_max, (*s.gyr_radps - r.session.gyro_bias_radps).norm());
    }
  }
  rest /= n;
  // White noise of 0.01 deg/s/sqrt(Hz) averaged over 5 s: 4e-5 rad/s; 5 sigma.
  EXPECT_LT((rest - r.session.gyro_bias_radps).norm(),
            5 * 0.01 * M_PI / 180 / std::sqrt(10.0) * std::sqrt(3.0));
  EXPECT_GT(moving_max, 0.1);  // tens of degrees per second while turning
}

// The simulated stream, cut into dwell windows, calibrates to the truth within 4 sigma: the
// simulator's Gauss-Markov bias wander and the calibrator's drift model agree.
TEST(SessionSim, DwellWindowsCalibrateToTheTruth) {
  for (const SensorClass& sensor : {IndustrialClass(), ConsumerClass()}) {
    SessionSimOptions o;
    o.sensor = sensor;
    o.rate_hz = 100;
    o.seed = 5;
    const SimRun r = Simulate(o);
    for (bool accel : {true, false}) {
      const MeasurementModel& model = accel ? *r.accel : *r.mag;
      Eigen::VectorXd truth = accel ? r.session.accel_truth : r.session.mag_truth;
      // The bias the drift-aware calibrator reports: the turn-on bias plus the wander over the
      // last pose.
      truth.tail<3>() +=
          accel ? r.session.LastPoseAccBiasOffset() : r.session.LastPoseMagBiasOffset();
      CalibratorOptions options = DriftOptionsForClass(model, sensor);
      Calibrator calibrator(options);
      std::string error;
      for (const auto& e : r.session.events) {
        ASSERT_TRUE(calibrator.add_pose(DwellRecord(r.session, e, model.sensor()), &error))
            << error;
      }
      const Estimate est = calibrator.solve();
      ASSERT_TRUE(est.ok) << est.error;
      for (int i = 0; i < est.theta.size(); ++i) {
        EXPECT_LT(std::abs(est.theta[i] - truth[i]) / est.sigma[i], 4.0)
            << sensor.name << " " << est.model << " " << est.parameters[i].name;
      }
    }
  }
}

}  // namespace
}  // namespace turncal
