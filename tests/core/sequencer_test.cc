// The position sequencer on simulated sessions (sim/session_sim.h): records per pose, their
// accuracy against the simulator's truth, windows clear of motion, early announcements, wrong
// announcements, schedule mode, progress. Bit flips, lost, saturated and non-finite samples and
// interruptions: sequencer_faults_test.cc; the dwell's own checks (creep, a stopped stream,
// stalls): sequencer_dwell_test.cc; backlogs and the host clock: host_clock_test.cc; the noise
// meter and stillness detector: noise_meter_test.cc.

#include <gtest/gtest.h>

#include "tests/core/sequencer_test_util.h"

namespace turncal {
namespace {

// Acceptance: a 26-pose session replayed gives exactly 26 records, each within 4 sigma of the
// simulator's true mean for its pose, each window clear of the table's motion.
TEST(Sequencer, AnnouncedSessionGivesOneAccurateRecordPerPose) {
  const Session s = Simulate();
  Collected c;
  Sequencer seq(SequencerOptions{}, Collect(&c));
  Replay(s, &seq);
  ASSERT_EQ(c.rejected.size(), 0u) << c.rejected[0].reason;
  ASSERT_EQ(c.captured.size(), 26u);
  const double sigma = AccSigma(s);
  const double mag_sigma = s.options.sensor.mag_noise_rms;
  double chi2 = 0;
  for (std::size_t i = 0; i < 26; ++i) {
    const auto& e = c.captured[i];
    const auto& ev = s.sim.events[i];
    ASSERT_EQ(e.index, ev.index);
    const PoseRecord& r = *e.record;
    ASSERT_TRUE(r.acc && r.gyr && r.mag && r.temp_c);
    // The window lies inside the dwell: after the table settled, before it moves again.
    EXPECT_GE(r.t_start_s, ev.t_s - 1e-9) << "pose " << i;
    EXPECT_LE(r.t_end_s, ev.dwell_end_s + 1e-9) << "pose " << i;
    EXPECT_EQ(r.acc->count, static_cast<std::int64_t>(std::ceil(3.0 * s.options.rate_hz)));
    const Eigen::Vector3d truth = s.accel->Predict(s.sim.accel_truth, ev.pose);
    const Eigen::Vector3d mag_truth = s.mag->Predict(s.sim.mag_truth, ev.pose);
    const double se = sigma / std::sqrt(static_cast<double>(r.acc->count));
    const double mag_se = mag_sigma / std::sqrt(static_cast<double>(r.mag->count));
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(r.acc->mean[a], truth[a], 4 * se) << "pose " << i << " axis " << a;
      EXPECT_NEAR(r.mag->mean[a], mag_truth[a], 4 * mag_se) << "pose " << i << " axis " << a;
      chi2 += std::pow((r.acc->mean[a] - truth[a]) / se, 2);
    }
    // The sample covariance estimates the white noise (4 sigma of a variance from n - 1 dof).
    const double n1 = static_cast<double>(r.acc->count - 1);
    EXPECT_NEAR(r.acc->covariance(0, 0) / (sigma * sigma), 1.0, 4 * std::sqrt(2 / n1));
  }
  // 78 standardised errors: chi^2 within 78 +- 4 sqrt(156).
  EXPECT_NEAR(chi2, 78, 4 * std::sqrt(156.0));
}

// A magnetometer at 50 Hz in the 100-Hz stream holds each value for two samples. The record's
// mag triad says so (values = half its samples), and its mean's covariance is the values'
// covariance / values: the means' standardised errors over the cube's 26 poses then have chi^2 of
// their 78 dof (counted by the samples it was twice that: the pipeline's mag13 at 10 Hz in 100 Hz
// had every sigma a factor 1.1 to 2.3 too small). Stillness holds on the held values too.
TEST(Sequencer, AMagnetometerSlowerThanTheStreamCountsItsValuesInTheRecord) {
  SessionSimOptions options;
  options.seed = 17;
  options.mag_rate_hz = 50.0;
  options.sensor.acc_bias_instability = options.sensor.mag_bias_instability = 0;
  const Session s = SimulateAccelMagSession(CubePoses26(), options);
  Collected c;
  Sequencer seq(SequencerOptions{}, Collect(&c));
  Replay(s, &seq);
  ASSERT_EQ(c.rejected.size(), 0u) << c.rejected[0].reason;
  ASSERT_EQ(c.captured.size(), 26u);
  double chi2 = 0;
  for (std::size_t i = 0; i < 26; ++i) {
    const PoseRecord& r = *c.captured[i].record;
    ASSERT_TRUE(r.acc && r.mag);
    EXPECT_EQ(r.acc->values, 0) << "pose " << i;
    EXPECT_NEAR(static_cast<double>(r.mag->values), 0.5 * static_cast<double>(r.mag->count), 1.0)
        << "pose " << i;
    const Eigen::Vector3d truth = s.mag->Predict(s.sim.mag_truth, s.sim.events[i].pose);
    const Eigen::Matrix3d w = SampleMeanCovariance(*r.mag);
    for (int a = 0; a < 3; ++a) chi2 += std::pow(r.mag->mean[a] - truth[a], 2) / w(a, a);
  }
  EXPECT_NEAR(chi2, 78, 4 * std::sqrt(156.0));
}

// Issue 19: each record also carries its window on the sensor's clock (what bias drift is timed
// in): the device clock, kept continuous where it resets. Here the device clock runs 20 ppm fast
// and resets to zero halfway; the sensor windows still advance with the session, pose by pose.
TEST(Sequencer, RecordsCarryTheirWindowOnTheSensorClockAcrossAClockReset) {
  const Session s = Simulate();
  Collected c;
  Sequencer seq(SequencerOptions{}, Collect(&c));
  const double reset_at = s.sim.events[13].dwell_end_s + 1.0;  // during the move to pose 14
  Replay(s, &seq, [&](Sample* x) {
    if (x->t_device_s && static_cast<double>(x->t_host_ns) * 1e-9 >= reset_at) {
      *x->t_device_s -= *s.sim.samples.front().t_device_s + reset_at;
    }
    return true;
  });
  ASSERT_EQ(c.captured.size(), 26u);
  for (std::size_t i = 0; i < c.captured.size(); ++i) {
    const PoseRecord& r = *c.captured[i].record;
    ASSERT_TRUE(r.has_sensor_window()) << "pose " << i;
    // 3 s of samples on either clock (the device's 20 ppm is 60 us here).
    EXPECT_NEAR(r.sensor_t_end_s - r.sensor_t_start_s, r.t_end_s - r.t_start_s, 1e-3);
    if (i == 0) continue;
    const PoseRecord& prev = *c.captured[i - 1].record;
    // Across the reset too, the sensor clock moved on by what the host saw (to 10 ms).
    EXPECT_NEAR(r.sensor_t_start_s - prev.sensor_t_start_s, r.t_start_s - prev.t_start_s, 0.01)
        << "pose " << i;
  }
}

TEST(Sequencer, EarlyAnnouncementWaitsUntilTheTableIsStill) {
  const Session s = Simulate();
  Collected c;
  Sequencer seq(SequencerOptions{}, Collect(&c));
  const double early = s.options.settle_s + 0.5;  // while the table still moves
  Replay(
      s, &seq, [](Sample*) { return true; }, 1, early);
  ASSERT_EQ(c.captured.size(), 26u);
  const auto& ev = s.sim.events[1];
  const PoseRecord& r = *c.captured[1].record;
  const double move_end = ev.t_s - s.options.settle_s;
  // Not one sample from the move; and none from the settling while its oscillation exceeded
  // the noise of one sample (amplitude x g below sigma from 0.3 s after the move for 2e-4 rad).
  EXPECT_GT(r.t_start_s, move_end + 0.3)
      << "window starts " << r.t_start_s - move_end << " s after the move";
  EXPECT_LE(r.t_end_s, ev.dwell_end_s + 1e-9);
  const Eigen::Vector3d truth = s.accel->Predict(s.sim.accel_truth, ev.pose);
  const double se = AccSigma(s) / std::sqrt(static_cast<double>(r.acc->count));
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(r.acc->mean[a], truth[a], 4 * se);
}

TEST(Sequencer, AnnouncementThatNeverSettlesIsRejectedWithTheReason) {
  const Session s = Simulate();
  Collected c;
  SequencerOptions o;
  o.still_timeout_s = 2.0;
  Sequencer seq(o, Collect(&c));
  // Pose 3 is announced 4 s early: during its whole move plus the end of pose 2's dwell, so the
  // table is never still for 2 s after it.
  const double early = s.options.move_s + s.options.settle_s;
  Replay(
      s, &seq, [](Sample*) { return true; }, 3, early);
  bool found = false;
  for (const auto& e : c.rejected) {
    if (e.index == 3) {
      found = true;
      EXPECT_NE(e.reason.find("not still within 2.0 s"), std::string::npos) << e.reason;
      EXPECT_NE(e.reason.find("last not-still window at t = "), std::string::npos) << e.reason;
    }
  }
  EXPECT_TRUE(found);
  EXPECT_EQ(c.captured.size(), 25u);
}

TEST(Sequencer, WrongAnnouncementIsRejected) {
  const Session s = Simulate();
  Collected c;
  Sequencer seq(SequencerOptions{}, Collect(&c));
  seq.SetPredictor(NominalAccPredictor(*s.accel));
  // Pose 4 is announced as pose 0's angles (the controller sent the wrong pose).
  std::size_t next = 0;
  for (const Sample& x : s.sim.samples) {
    while (next < s.sim.events.size() && Ns(s.sim.events[next].t_s) <= x.t_host_ns) {
      Announcement a;
      a.index = s.sim.events[next].index;
      a.pose = next == 4 ? s.sim.events[0].pose : s.sim.events[next].pose;
      a.t_host_ns = Ns(s.sim.events[next].t_s);
      std::string error;
      seq.Announce(a, &error);
      ++next;
    }
    seq.Push(x);
  }
  seq.Finish(s.sim.samples.back().t_host_ns);
  ExpectOneRejection(c, 4, "wrong announcement");
  EXPECT_EQ(c.captured.size(), 25u);
}

// Schedule mode on the same session without announcements gives the same records: same poses
// in the same order, means equal within what the two windows' non-shared samples allow.
TEST(Sequencer, ScheduleModeGivesTheSameRecords) {
  const Session s = Simulate();
  Collected announced, scheduled;
  {
    Sequencer seq(SequencerOptions{}, Collect(&announced));
    Replay(s, &seq);
  }
  Sequencer seq(SequencerOptions{}, Collect(&scheduled));
  std::string error;
  ASSERT_TRUE(seq.SetSchedule(s.poses, &error)) << error;
  for (const Sample& x : s.sim.samples) seq.Push(x);
  seq.Finish(s.sim.samples.back().t_host_ns);
  ASSERT_EQ(scheduled.captured.size(), 26u);
  ASSERT_EQ(announced.captured.size(), 26u);
  const double sigma = AccSigma(s);
  for (std::size_t i = 0; i < 26; ++i) {
    const PoseRecord& a = *announced.captured[i].record;
    const PoseRecord& b = *scheduled.captured[i].record;
    EXPECT_EQ(a.pose.phi_rad, b.pose.phi_rad);
    EXPECT_EQ(a.pose.psi_rad, b.pose.psi_rad);
    // Inside the same dwell.
    const auto& ev = s.sim.events[i];
    EXPECT_GE(b.t_start_s, ev.t_s - s.options.settle_s + 0.3);
    EXPECT_LE(b.t_end_s, ev.dwell_end_s + 1e-9);
    // Samples in one window only: m; difference of the means has sigma sqrt(2 m) sigma / n.
    const double n = static_cast<double>(a.acc->count);
    const double m = std::min(n, std::abs(a.t_start_s - b.t_start_s) * s.options.rate_hz + 1);
    const double sd = std::sqrt(2 * m) * sigma / n;
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(a.acc->mean[k], b.acc->mean[k], 4 * sd + 1e-12);
  }
  ASSERT_FALSE(scheduled.events.empty());
  EXPECT_EQ(scheduled.events.back().kind, SequencerEventKind::kScheduleEnd);
  EXPECT_NE(scheduled.events.back().reason.find("all 26 scheduled poses captured"),
            std::string::npos)
      << scheduled.events.back().reason;
}

TEST(Sequencer, ScheduleWithTheWrongOrderSaysSo) {
  const Session s = Simulate();
  Collected c;
  Sequencer seq(SequencerOptions{}, Collect(&c));
  seq.SetPredictor(NominalAccPredictor(*s.accel));
  std::vector<TablePose> poses = s.poses;
  std::swap(poses[1], poses[2]);
  std::string error;
  ASSERT_TRUE(seq.SetSchedule(poses, &error));
  for (const Sample& x : s.sim.samples) seq.Push(x);
  seq.Finish(s.sim.samples.back().t_host_ns);
  ASSERT_FALSE(c.skipped.empty());
  EXPECT_NE(c.skipped[0].reason.find("is the schedule's order wrong?"), std::string::npos)
      << c.skipped[0].reason;
  EXPECT_EQ(c.events.back().kind, SequencerEventKind::kScheduleEnd);
  EXPECT_NE(c.events.back().reason.find("fewer usable still segments"), std::string::npos)
      << c.events.back().reason;
}

TEST(Sequencer, ProgressEventsCountUpToTheDwell) {
  const Session s = Simulate();
  Collected c;
  Sequencer seq(SequencerOptions{}, Collect(&c));
  Replay(s, &seq);
  int progress = 0;
  std::int64_t last = 0;
  for (const auto& e : c.events) {
    if (e.index != 0) continue;
    if (e.kind == SequencerEventKind::kProgress) {
      ++progress;
      EXPECT_GT(e.collected, last);
      EXPECT_LT(e.collected, e.needed);
      last = e.collected;
    }
  }
  EXPECT_GE(progress, 8);
  EXPECT_LE(progress, 10);
  EXPECT_EQ(c.events.front().kind, SequencerEventKind::kNoiseMeasured);
}

TEST(Sequencer, ConfiguredNoiseForADeviceWithoutMagnetometer) {
  Session s = Simulate();
  for (auto& x : s.sim.samples) x.mag.reset();
  SequencerOptions o;
  o.noise = NoiseProfileForClass(s.options.sensor, s.options.rate_hz, true);
  Collected c;
  Sequencer seq(o, Collect(&c));
  Replay(s, &seq);
  EXPECT_EQ(c.captured.size(), 26u);
  EXPECT_EQ(seq.totals().flagged, 0);
}

}  // namespace
}  // namespace turncal
