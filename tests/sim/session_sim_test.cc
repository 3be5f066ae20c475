#include "sim/session_sim.h"

#include <gtest/gtest.h>

#include <cmath>
#include <utility>
#include <vector>

#include "core/estimation/calibrator.h"
#include "tests/support/simulated_session.h"

namespace turncal {
namespace {

SimulatedRun Simulate(const SessionSimOptions& o, int n_poses = 36) {
  std::vector<TablePose> poses = DefaultSessionPoses();
  poses.resize(static_cast<std::size_t>(n_poses));
  return SimulateAccelMagSession(std::move(poses), o);
}

TEST(SessionSim, TimelineEventsAndDeterminism) {
  SessionSimOptions o;
  o.rate_hz = 100;
  o.dwell_s = 2;
  const SimulatedRun a = Simulate(o, 5), b = Simulate(o, 5);
  ASSERT_EQ(a.sim.events.size(), 5u);
  EXPECT_NEAR(a.sim.duration_s, o.start_s + 5 * (o.move_s + o.settle_s + o.dwell_s), 1e-9);
  EXPECT_EQ(a.sim.samples.size(), static_cast<std::size_t>(a.sim.duration_s * o.rate_hz));
  ASSERT_EQ(a.sim.samples.size(), b.sim.samples.size());
  for (std::size_t i = 0; i < a.sim.samples.size(); i += 97) {
    EXPECT_EQ(*a.sim.samples[i].acc_mps2, *b.sim.samples[i].acc_mps2);
  }
  // The device clock runs 20 ppm fast from 10 s.
  const auto& last = a.sim.samples.back();
  EXPECT_NEAR(*last.t_device_s - 10.0, last.t_host_ns * 1e-9 * (1 + 20e-6), 1e-9);
}

// The bias's wander over a window: the mean over the samples inside, and for a window with none
// inside (one sample period long, shifted by microseconds: a free fit's last magnetometer value
// at 100 Hz) the wander at the nearest sample -- not zero, which had made the hand Monte Carlo's
// hard iron look dishonest at 100 Hz (std z 1.75).
TEST(SessionSim, DriftOverAWindowWithoutASampleIsTheNearestSamples) {
  SessionSimOptions o;
  o.rate_hz = 100;
  o.dwell_s = 2;
  const SimulatedRun r = Simulate(o, 3);
  const SimulatedSession& s = r.sim;
  const std::size_t k = s.samples.size() - 1;
  const double tk = static_cast<double>(s.samples[k].t_host_ns) * 1e-9;
  const Eigen::Vector3d at_k = s.MagDriftMean(tk, tk + 0.01);  // the last sample only
  EXPECT_GT(at_k.norm(), 0.0);
  EXPECT_EQ(s.MagDriftMean(tk + 1e-6, tk + 0.01 + 1e-6), at_k);  // after the last: the last
  const double t_mid = static_cast<double>(s.samples[k / 2].t_host_ns) * 1e-9;
  EXPECT_EQ(s.MagDriftMean(t_mid - 0.004, t_mid + 0.004), s.MagDriftMean(t_mid, t_mid + 0.001));
  EXPECT_EQ(s.AccDriftMean(t_mid + 0.001, t_mid + 0.004),
            s.AccDriftMean(t_mid, t_mid + 0.001));  // nearer the sample at t_mid than the next
  // Two samples inside: their mean.
  const Eigen::Vector3d two = s.MagDriftMean(t_mid, t_mid + 0.015);
  const Eigen::Vector3d next = s.MagDriftMean(t_mid + 0.01, t_mid + 0.011);
  EXPECT_NEAR((two - 0.5 * (s.MagDriftMean(t_mid, t_mid + 0.001) + next)).norm(), 0.0, 1e-15);
}

TEST(SessionSim, GyroSeesTheTableMoveAndOnlyItsBiasAtRest) {
  SessionSimOptions o;
  o.rate_hz = 200;
  const SimulatedRun r = Simulate(o, 3);
  const auto& e = r.sim.events[1];
  Eigen::Vector3d rest = Eigen::Vector3d::Zero();
  int n = 0;
  double moving_max = 0;
  for (const auto& s : r.sim.samples) {
    const double t = s.t_host_ns * 1e-9;
    if (t >= e.t_s && t < e.dwell_end_s) {
      rest += *s.gyr_radps;
      ++n;
    }
    if (t > e.t_s - o.settle_s - o.move_s + 0.5 && t < e.t_s - o.settle_s - 0.5) {
      moving_max = std::max(moving_max, (*s.gyr_radps - r.sim.gyro_bias_radps).norm());
    }
  }
  rest /= n;
  // White noise of 0.01 deg/s/sqrt(Hz) averaged over 5 s: 4e-5 rad/s; 5 sigma.
  EXPECT_LT((rest - r.sim.gyro_bias_radps).norm(),
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
    const SimulatedRun r = Simulate(o);
    for (bool accel : {true, false}) {
      const MeasurementModel& model = accel ? *r.accel : *r.mag;
      Eigen::VectorXd truth = accel ? r.sim.accel_truth : r.sim.mag_truth;
      // The bias the drift-aware calibrator reports: the turn-on bias plus the wander over the
      // last pose.
      truth.tail<3>() += accel ? r.sim.LastPoseAccBiasOffset() : r.sim.LastPoseMagBiasOffset();
      CalibratorOptions options = DriftOptionsForClass(model, sensor);
      Calibrator calibrator(options);
      std::string error;
      for (const auto& e : r.sim.events) {
        ASSERT_TRUE(calibrator.add_pose(DwellRecord(r.sim, e, model.sensor()), &error)) << error;
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
