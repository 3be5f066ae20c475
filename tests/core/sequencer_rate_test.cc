// Issue 21: the sequencer's rate segments -- whole revolutions of a steady gyro rate, announced
// by the controller, on simulated sessions with static poses between them.

#include <gtest/gtest.h>

#include <cmath>

#include "core/estimation/calibrator.h"
#include "core/frames/units.h"
#include "core/sequencing/sequencer.h"
#include "sim/session_sim.h"

namespace turncal {
namespace {

std::int64_t Ns(double t_s) { return static_cast<std::int64_t>(std::llround(t_s * 1e9)); }

struct RateRun {
  std::unique_ptr<MeasurementModel> accel, mag, gyro;
  SimulatedSession sim;
  std::vector<SequencerEvent> captured, rejected;
};

// Static cube poses interleaved with the default rate segments, announced at the simulator's
// event times (a rate announcement may be changed by `edit`).
RateRun Simulate(const std::string& gyro_model, std::uint64_t seed,
                 const std::function<void(Announcement*)>& edit = {},
                 const std::function<bool(Sample*)>& transform = {}) {
  RateRun r;
  std::string error;
  r.accel = MakeModel("accel13", ModelContext{}, &error);
  r.mag = MakeModel("mag13", ModelContext{}, &error);
  r.gyro = MakeModel(gyro_model, ModelContext{}, &error);
  std::vector<TablePose> poses;
  const auto cube = CubePoses26();
  const auto rates = DefaultRateSegments(90.0);
  for (std::size_t i = 0; i < std::max(cube.size(), rates.size()); ++i) {
    if (i < cube.size()) poses.push_back(cube[i]);
    if (i < rates.size()) poses.push_back(rates[i]);
  }
  SessionSimOptions o;
  o.rate_hz = 100;
  o.seed = seed;
  r.sim = SimulateSession(*r.accel, *r.mag, poses, o, r.gyro.get());
  SequencerOptions so;
  Sequencer seq(so, [&r](const SequencerEvent& e) {
    if (e.kind == SequencerEventKind::kCaptured) r.captured.push_back(e);
    if (e.kind == SequencerEventKind::kRejected) r.rejected.push_back(e);
  });
  std::size_t next = 0;
  for (const Sample& raw : r.sim.samples) {
    while (next < r.sim.events.size() && Ns(r.sim.events[next].t_s) <= raw.t_host_ns) {
      const SessionPoseEvent& ev = r.sim.events[next];
      Announcement a;
      a.index = ev.index;
      a.pose = ev.pose;
      a.t_host_ns = Ns(ev.t_s);
      if (edit && a.pose.is_rate()) edit(&a);
      EXPECT_TRUE(seq.Announce(a, &error)) << error;
      ++next;
    }
    Sample x = raw;
    if (!transform || transform(&x)) seq.Push(x);
  }
  seq.Finish(r.sim.samples.back().t_host_ns);
  return r;
}

TEST(SequencerRate, CapturesWholeRevolutionsOfTheGyroOnly) {
  const RateRun r = Simulate("gyro12", 11);
  ASSERT_TRUE(r.rejected.empty()) << r.rejected.front().reason;
  ASSERT_EQ(r.captured.size(), r.sim.events.size());
  int rates = 0;
  for (const auto& e : r.captured) {
    ASSERT_TRUE(e.record);
    const PoseRecord& rec = *e.record;
    if (!rec.pose.is_rate()) {
      EXPECT_TRUE(rec.acc && rec.gyr);
      continue;
    }
    ++rates;
    EXPECT_FALSE(rec.acc) << "a rate segment's accelerometer is not stationary";
    EXPECT_FALSE(rec.mag);
    ASSERT_TRUE(rec.gyr);
    // Whole revolutions at the announced rate (100 Hz: within half a sample).
    const double turn_s = 2 * M_PI / std::abs(rec.pose.rate_radps);
    const double turns = static_cast<double>(rec.gyr->count) / 100.0 / turn_s;
    EXPECT_NEAR(turns, std::round(turns), 0.5 / 100.0 / turn_s + 1e-9);
    EXPECT_GE(static_cast<double>(rec.gyr->count) / 100.0, 3.0 - 0.01);  // the dwell
    // The mean is the model's prediction within the white noise's 5 sigma and the ripple.
    const Eigen::Vector3d predicted = r.gyro->Predict(r.sim.gyro_truth, rec.pose);
    const double white = IndustrialClass().gyr_noise_density * std::sqrt(100.0 / 2) /
                         std::sqrt(static_cast<double>(rec.gyr->count));
    // The bias wanders (10 deg/h at most a few sigma) and the ripple leaves 1e-4 of the rate.
    const double allowance = 5 * white + 1e-4 * std::abs(rec.pose.rate_radps) + 2e-4;
    EXPECT_LT((rec.gyr->mean - predicted).cwiseAbs().maxCoeff(), allowance)
        << ToString(rec.pose.rate_axis) << " " << rec.pose.rate_radps * kDegPerRad;
  }
  EXPECT_EQ(rates, 16);
}

TEST(SequencerRate, TheRecordsCalibrateGyro21WithinFourSigma) {
  const RateRun r = Simulate("gyro21", 12);
  ASSERT_TRUE(r.rejected.empty()) << r.rejected.front().reason;
  Calibrator calibrator(DriftOptionsForClass(*r.gyro, IndustrialClass()));
  std::string error;
  for (const auto& e : r.captured) ASSERT_TRUE(calibrator.add_pose(*e.record, &error)) << error;
  const Estimate est = calibrator.solve();
  ASSERT_TRUE(est.ok) << est.error;
  Eigen::VectorXd truth = r.sim.gyro_truth;
  const auto& last = r.captured.back().record;
  truth.segment<3>(r.gyro->index_of("bx")) += r.sim.GyrDriftMean(last->t_start_s, last->t_end_s);
  for (int i = 0; i < est.theta.size(); ++i) {
    EXPECT_LT(std::abs(est.theta[i] - truth[i]) / est.sigma[i], 4.0)
        << est.parameters[i].name << " est " << est.theta[i] << " truth " << truth[i];
  }
}

TEST(SequencerRate, AWrongRateIsRejectedWithTheReason) {
  // The controller says 45 deg/s where the table turns at 90.
  const RateRun r = Simulate("gyro12", 13, [](Announcement* a) { a->pose.rate_radps /= 2; });
  ASSERT_EQ(r.rejected.size(), 16u);
  EXPECT_NE(r.rejected.front().reason.find("announced rate"), std::string::npos)
      << r.rejected.front().reason;
}

TEST(SequencerRate, ARateThatStopsDuringTheWindowIsRejected) {
  // The gyro freezes at zero for a second inside the first rate segment's window (a stalled
  // table): the rate is not steady.
  double t0 = 0;
  const RateRun r = Simulate(
      "gyro12", 14,
      [&t0](Announcement* a) {
        if (t0 == 0) t0 = a->t_host_ns * 1e-9;
      },
      [&t0](Sample* s) {
        const double t = s->t_host_ns * 1e-9;
        if (t0 > 0 && t > t0 + 2.0 && t < t0 + 3.0) *s->gyr_radps = Eigen::Vector3d::Zero();
        return true;
      });
  ASSERT_GE(r.rejected.size(), 1u);
  EXPECT_NE(r.rejected.front().reason.find("not steady"), std::string::npos)
      << r.rejected.front().reason;
}

TEST(SequencerRate, SchedulesHoldStaticPosesOnly) {
  Sequencer seq(SequencerOptions{}, {});
  std::string error;
  EXPECT_FALSE(seq.SetSchedule(DefaultRateSegments(), &error));
  EXPECT_NE(error.find("rate segments are announced"), std::string::npos);
  Announcement a;
  a.pose.rate_axis = TableAxis::kInner;
  a.pose.rate_radps = 0;
  EXPECT_FALSE(seq.Announce(a, &error));
  EXPECT_NE(error.find("0.1 to 2000 deg/s"), std::string::npos);
}

}  // namespace
}  // namespace turncal
