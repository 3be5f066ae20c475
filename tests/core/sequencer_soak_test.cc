// The chamber's soak (core/sequencing/soak.h, issue 36): with a set-point announced, a pose waits
// until the sensor's temperature has stopped moving, says why while it waits (POSE_WAITING), and
// is rejected with the soak's state when the chamber never settles; without one, poses are taken
// at once whatever the temperature does. Once the temperature has settled, the bias must too: a
// bias still relaxing at a settled temperature holds the pose, with the axis and the change as the
// reason.

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "core/sequencing/soak.h"
#include "tests/core/sequencer_test_util.h"

namespace turncal {
namespace {

// The die settling towards 40 degC from 25 with a 20 s time constant: its rate falls below
// 0.05 degC/min after about 140 s of the session.
bool Settling(Sample* s) {
  const double t = static_cast<double>(s->t_host_ns) * 1e-9;
  s->temp_c = 40.0 - 15.0 * std::exp(-t / 20.0);
  return true;
}

TEST(SequencerSoak, PosesWaitUntilTheTemperatureHasSettledAndSayWhy) {
  const Session s = Simulate();
  Collected c;
  Sequencer seq(SequencerOptions{}, Collect(&c));
  SoakOptions soak;
  soak.setpoint_c = 40.0;
  soak.max_rate_c_per_min = 0.05;
  soak.window_s = 30.0;
  soak.check_bias = false;  // the cube's poses rest a few seconds: the temperature alone here
  seq.SetSoak(soak);
  Replay(s, &seq, Settling);
  std::vector<std::string> waiting;
  for (const auto& e : c.events) {
    if (e.kind == SequencerEventKind::kSoakWaiting) waiting.push_back(e.reason);
  }
  ASSERT_FALSE(waiting.empty());
  EXPECT_NE(waiting.back().find("waiting for the soak at 40.0 degC"), std::string::npos)
      << waiting.back();
  EXPECT_NE(waiting.back().find("degC/min (settled below 0.05 over 30 s)"), std::string::npos)
      << waiting.back();
  // Every record was taken once the temperature moved by less than 0.05 degC/min over the
  // window before it (exactly: 45 exp(-t/20) degC/min falls below 0.05 at t = 136 s; the fitted
  // slope over 30 s lags by less than the window).
  ASSERT_FALSE(c.captured.empty());
  for (const auto& e : c.captured) EXPECT_GT(e.record->t_start_s, 136.0 - 1e-9);
  EXPECT_GT(c.captured.size(), 5u);
  // The poses announced while it moved were superseded while they waited, none captured early.
  EXPECT_EQ(c.captured.size() + c.rejected.size(), s.sim.events.size());
  EXPECT_TRUE(std::isfinite(c.captured.front().record->temp_c.value_or(NAN)));

  // The same session without a soak: every pose at once.
  Collected free_run;
  Sequencer plain(SequencerOptions{}, Collect(&free_run));
  Replay(s, &plain, Settling);
  EXPECT_EQ(free_run.captured.size(), s.sim.events.size());
}

TEST(SequencerSoak, AChamberThatNeverSettlesRejectsThePoseWithTheSoaksState) {
  const Session s = Simulate();
  Collected c;
  Sequencer seq(SequencerOptions{}, Collect(&c));
  SoakOptions soak;
  soak.setpoint_c = 70.0;
  soak.window_s = 5.0;
  soak.timeout_s = 6.0;
  seq.SetSoak(soak);
  // A chamber ramping at 1 degC/min and never reaching 70.
  Replay(s, &seq, [](Sample* x) {
    x->temp_c = 20.0 + static_cast<double>(x->t_host_ns) * 1e-9 / 60.0;
    return true;
  });
  EXPECT_TRUE(c.captured.empty());
  ASSERT_FALSE(c.rejected.empty());
  bool timed_out = false;
  for (const auto& e : c.rejected) {
    if (e.reason.find("the soak did not settle within 6 s") != std::string::npos) {
      timed_out = true;
      EXPECT_NE(e.reason.find("moves +1.00 degC/min"), std::string::npos) << e.reason;
      EXPECT_NE(e.reason.find("from the set-point"), std::string::npos) << e.reason;
    }
  }
  EXPECT_TRUE(timed_out);
}

// The table resting at one pose for 240 s at 100 Hz, the temperature settled at 40 degC from the
// start, the accelerometer's z bias relaxing by `relax_mps2` exp(-t / 20 s) (a package's stress
// after the die settled); the pose announced at 2 s. Returns the first capture's start (NaN: none)
// and the soak's reasons.
double RestingPoseCapturedAt(double relax_mps2, bool check_bias, std::vector<std::string>* why) {
  Collected c;
  Sequencer seq(SequencerOptions{}, Collect(&c));
  SoakOptions soak;
  soak.setpoint_c = 40.0;
  soak.window_s = 30.0;
  soak.check_bias = check_bias;
  seq.SetSoak(soak);
  std::mt19937_64 rng(11);
  std::normal_distribution<double> normal;
  bool announced = false;
  for (int i = 0; i < 24000; ++i) {
    const double t = i / 100.0;
    if (!announced && t >= 2.0) {
      Announcement a;
      a.index = 0;
      a.t_host_ns = Ns(t);
      std::string error;
      EXPECT_TRUE(seq.Announce(a, &error)) << error;
      announced = true;
    }
    Sample x;
    x.t_host_ns = Ns(t);
    x.acc_mps2 = Eigen::Vector3d(0.01 * normal(rng), 0.01 * normal(rng),
                                 -9.81 + 0.01 * normal(rng) + relax_mps2 * std::exp(-t / 20.0));
    x.mag = Eigen::Vector3d(0.2 + 1e-3 * normal(rng), 1e-3 * normal(rng), 0.4 + 1e-3 * normal(rng));
    x.temp_c = 40.0 + 0.01 * normal(rng);
    seq.Push(x);
  }
  seq.Finish(Ns(240.0));
  for (const auto& e : c.events) {
    if (e.kind == SequencerEventKind::kSoakWaiting) why->push_back(e.reason);
  }
  return c.captured.empty() ? NAN : c.captured.front().record->t_start_s;
}

TEST(SequencerSoak, ABiasStillRelaxingAtASettledTemperatureHoldsThePose) {
  // Without a transient: taken once both windows have filled (80 % of 30 s after the start).
  std::vector<std::string> why;
  const double quiet = RestingPoseCapturedAt(0.0, true, &why);
  ASSERT_TRUE(std::isfinite(quiet));
  EXPECT_LT(quiet, 40.0);
  // 0.05 m/s^2 relaxing with tau 20 s: the means of a 30-s window's halves differ by about
  // 0.039 e^-(t - 15) / 20 m/s^2 (t the window's end), against the stillness detector's limit of
  // 2.2e-3 (sigma 0.01 per sample, 1500 samples a half): taken at 77 s here; at 25 s unchecked.
  why.clear();
  const double relaxing = RestingPoseCapturedAt(0.05, true, &why);
  ASSERT_TRUE(std::isfinite(relaxing));
  EXPECT_GT(relaxing, 45.0);
  EXPECT_LT(relaxing, 120.0);
  bool named = false;
  for (const std::string& w : why) {
    named = named || w.find("the bias still moves: acc z changed by -") != std::string::npos;
  }
  EXPECT_TRUE(named) << (why.empty() ? "no reason" : why.back());
  // The temperature alone (check_bias = false) would have taken it with the bias still moving.
  why.clear();
  EXPECT_LT(RestingPoseCapturedAt(0.05, false, &why), 40.0);
}

TEST(SequencerSoak, TheTrackersSlopeIsTheLeastSquaresLine) {
  SoakTracker t;
  for (int i = 0; i <= 100; ++i) t.Add(i * 0.1, 30.0 + 0.5 * (i * 0.1) / 60.0, 60.0);
  EXPECT_FALSE(t.RateCPerMin(60.0).has_value());  // 10 s of the 60 watched
  for (int i = 101; i <= 700; ++i) t.Add(i * 0.1, 30.0 + 0.5 * (i * 0.1) / 60.0, 60.0);
  ASSERT_TRUE(t.RateCPerMin(60.0).has_value());
  EXPECT_NEAR(*t.RateCPerMin(60.0), 0.5, 1e-9);
  std::string why;
  SoakOptions soak;
  EXPECT_FALSE(t.Settled(soak, &why));
  soak.max_rate_c_per_min = 0.6;
  EXPECT_TRUE(t.Settled(soak, &why));
  EXPECT_FALSE(SoakOptions{.setpoint_c = NAN}.IsValid(&why));

  // A channel stuck at one reading, degrees from the set-point, is not a settled soak.
  SoakTracker stuck;
  for (int i = 0; i <= 700; ++i) stuck.Add(i * 0.1, 23.0, 60.0);
  soak.setpoint_c = 40.0;
  EXPECT_FALSE(stuck.Settled(soak, &why));
  EXPECT_NE(why.find("a stuck temperature channel?"), std::string::npos) << why;
  soak.setpoint_c = 23.5;  // close to the set-point: a settled die that reports 0.1 degC steps
  EXPECT_TRUE(stuck.Settled(soak, &why));
}

}  // namespace
}  // namespace turncal
