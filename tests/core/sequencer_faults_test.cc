// The position sequencer on simulated sessions with faults: bit flips that got past a checksum,
// lost, saturated and non-finite samples, gaps in a scheduled segment, corrupted counters.

#include <gtest/gtest.h>

#include "tests/core/sequencer_test_util.h"

namespace turncal {
namespace {

// Flips one random bit of a float32 copy of one axis value in about one sample in 80.
struct BitFlipper {
  std::mt19937_64 rng{11};
  int flips = 0;
  void operator()(Sample* s) {
    if (std::uniform_int_distribution<int>(0, 79)(rng) != 0) return;
    Eigen::Vector3d* v = &*s->acc_mps2;
    const int which = std::uniform_int_distribution<int>(0, 2)(rng);
    if (which == 1) v = &*s->gyr_radps;
    if (which == 2) v = &*s->mag;
    const int axis = std::uniform_int_distribution<int>(0, 2)(rng);
    const int bit = std::uniform_int_distribution<int>(0, 31)(rng);
    auto f = std::bit_cast<std::uint32_t>(static_cast<float>((*v)[axis]));
    f ^= 1u << bit;
    (*v)[axis] = static_cast<double>(std::bit_cast<float>(f));
    ++flips;
  }
};

// Bit flips that got past a checksum (on the wire, checksums catch every single-bit flip:
// tests/daemon/sequencer_replay_test.cc). A flip that moves a value beyond the outlier limit
// (5 robust sigmas) must be excluded; one inside it is indistinguishable from noise and may move
// a mean by at most its own size / n. The test checks both against the exact comparison: the
// clean stream without the samples the sequencer excluded and with the original values of the
// flipped samples it used.
TEST(Sequencer, BitFlipsBeyondTheNoiseAreExcludedAndTheRestAreBounded) {
  const Session s = Simulate();
  auto round = [](Sample* x) {
    for (auto* v : {&*x->acc_mps2, &*x->gyr_radps, &*x->mag}) {
      for (int a = 0; a < 3; ++a) (*v)[a] = static_cast<double>(static_cast<float>((*v)[a]));
    }
  };
  std::vector<Sample> clean_samples = s.sim.samples, dirty_samples;
  for (auto& x : clean_samples) round(&x);
  dirty_samples = clean_samples;
  std::vector<char> flipped(dirty_samples.size(), 0);
  BitFlipper flipper;
  for (std::size_t i = 0; i < dirty_samples.size(); ++i) {
    const int before = flipper.flips;
    flipper(&dirty_samples[i]);
    flipped[i] = flipper.flips != before;
  }
  std::map<std::int64_t, std::string> excluded;
  Collected dirty;
  Session with = Simulate();
  with.sim.samples = dirty_samples;
  Sequencer seq(SequencerOptions{}, Collect(&dirty));
  seq.SetExclusionObserver(
      [&](const StillSample& x, const char* why) { excluded[x.t_host_ns] = why; });
  Replay(with, &seq);
  ASSERT_EQ(dirty.captured.size(), 26u);
  EXPECT_GT(flipper.flips, 250);

  Session without = Simulate();
  without.sim.samples.clear();
  for (const auto& x : clean_samples) {
    if (!excluded.count(x.t_host_ns)) without.sim.samples.push_back(x);
  }
  Collected clean;
  {
    Sequencer seq2(SequencerOptions{}, Collect(&clean));
    Replay(without, &seq2);
  }
  ASSERT_EQ(clean.captured.size(), 26u);
  const std::array<double, 3> sigma = {
      AccSigma(s), s.options.sensor.gyr_noise_density * std::sqrt(s.options.rate_hz / 2.0),
      s.options.sensor.mag_noise_rms};
  int gross_in_windows = 0, small_in_windows = 0;
  double worst = 0;
  for (std::size_t p = 0; p < 26; ++p) {
    const PoseRecord& a = *clean.captured[p].record;
    const PoseRecord& b = *dirty.captured[p].record;
    ASSERT_EQ(a.t_start_s, b.t_start_s) << "pose " << p;
    // The leverage of the flips the sequencer used, per triad and axis.
    std::array<Eigen::Vector3d, 3> allowed{Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
                                           Eigen::Vector3d::Zero()};
    for (std::size_t i = 0; i < dirty_samples.size(); ++i) {
      const double t = dirty_samples[i].t_host_ns * 1e-9;
      if (!flipped[i] || t < a.t_start_s || t >= a.t_end_s) continue;
      const auto& d = dirty_samples[i];
      const auto& c = clean_samples[i];
      const std::array<Eigen::Vector3d, 3> delta = {*d.acc_mps2 - *c.acc_mps2,
                                                    *d.gyr_radps - *c.gyr_radps, *d.mag - *c.mag};
      double size = 0;  // in noise sigmas
      for (int t3 = 0; t3 < 3; ++t3) {
        size = std::max(size, delta[t3].array().abs().maxCoeff() / sigma[t3]);
      }
      if (size > 6) {
        ++gross_in_windows;
        EXPECT_TRUE(excluded.count(d.t_host_ns)) << "a flip of " << size << " sigma was used";
      } else if (!excluded.count(d.t_host_ns)) {
        ++small_in_windows;
        EXPECT_LT(size, 5.5) << "used flip beyond the outlier limit";
        for (int t3 = 0; t3 < 3; ++t3) {
          allowed[t3] += delta[t3].cwiseAbs() / static_cast<double>(b.acc->count);
        }
      }
    }
    for (int t3 : {0, 2}) {
      const TriadStats& ta = t3 == 0 ? *a.acc : *a.mag;
      const TriadStats& tb = t3 == 0 ? *b.acc : *b.mag;
      EXPECT_EQ(ta.count, tb.count);
      for (int k = 0; k < 3; ++k) {
        const double shift = std::abs(ta.mean[k] - tb.mean[k]);
        EXPECT_LE(shift, allowed[t3][k] + 1e-12) << "pose " << p << " triad " << t3;
        const double se = std::sqrt(ta.covariance(k, k) / static_cast<double>(ta.count));
        worst = std::max(worst, shift / se);
      }
    }
  }
  EXPECT_GT(gross_in_windows, 10);
  RecordProperty("worst_shift_sigma", std::to_string(worst));
  std::printf(
      "bit flips: %d; in windows: %d gross (all excluded), %d within the noise (used); largest "
      "shift of a mean %.3f sigma\n",
      flipper.flips, gross_in_windows, small_in_windows, worst);
}

TEST(Sequencer, LostSamplesAreCountedAndTooManyRejectThePose) {
  const Session s = Simulate();
  // During pose 5's dwell, every 10th sample is lost (its counter skips): 10 % lost at random
  // leaves the mean unbiased, the pose is captured with the loss counted. With 2 of every 3
  // lost (67 % > max_lost_fraction 50 %) it is rejected.
  const auto& ev = s.sim.events[5];
  for (const int keep_one_in : {0, 3}) {
    Collected c;
    Sequencer seq(SequencerOptions{}, Collect(&c));
    Replay(s, &seq, [&](Sample* x) {
      const double t = x->t_host_ns * 1e-9;
      if (!(t > ev.t_s && t < ev.dwell_end_s)) return true;
      return keep_one_in == 0 ? *x->counter % 10 != 0 : *x->counter % 3 == 0;
    });
    if (keep_one_in == 0) {
      ASSERT_EQ(c.captured.size(), 26u);
      ASSERT_TRUE(c.rejected.empty()) << c.rejected[0].reason;
      const auto& r = c.captured[5];
      EXPECT_EQ(r.index, 5);
      EXPECT_NEAR(static_cast<double>(r.counts.lost) / static_cast<double>(r.needed), 0.1, 0.02);
      continue;
    }
    ASSERT_EQ(c.captured.size(), 25u);
    ASSERT_EQ(c.rejected.size(), 1u);
    EXPECT_EQ(c.rejected[0].index, 5);
    EXPECT_NE(c.rejected[0].reason.find("too many lost samples"), std::string::npos)
        << c.rejected[0].reason;
    EXPECT_NEAR(
        static_cast<double>(c.rejected[0].counts.lost) / static_cast<double>(c.rejected[0].needed),
        2.0 / 3.0, 0.03);
  }
}

// Replays `s` with `corrupt` applied to every sample read in (ev.t_s + from_s, ev.t_s + to_s):
// the number of samples it corrupted.
template <typename Corrupt>
int ReplayCorrupting(const Session& s, Sequencer* seq, const SessionPoseEvent& ev, double from_s,
                     double to_s, Corrupt corrupt) {
  int corrupted = 0;
  Replay(s, seq, [&](Sample* x) {
    const double t = x->t_host_ns * 1e-9;
    if (t > ev.t_s + from_s && t < ev.t_s + to_s) {
      corrupt(x);
      ++corrupted;
    }
    return true;
  });
  return corrupted;
}

TEST(Sequencer, SaturatedSamplesAreExcludedAndCounted) {
  const Session s = Simulate();
  Collected c;
  Sequencer seq(SequencerOptions{}, Collect(&c));
  const auto& ev = s.sim.events[2];
  const int saturated = ReplayCorrupting(s, &seq, ev, 1.0, 1.03, [](Sample* x) {
    x->acc_mps2->x() = 16 * 9.80665;
    x->flags |= kAccSaturated;
  });
  ASSERT_EQ(c.captured.size(), 26u);
  EXPECT_EQ(c.captured[2].counts.flagged, saturated);
  const Eigen::Vector3d truth = s.accel->Predict(s.sim.accel_truth, ev.pose);
  const auto& r = *c.captured[2].record;
  EXPECT_NEAR(r.acc->mean.x(), truth.x(), 4 * AccSigma(s) / std::sqrt(r.acc->count));
}

TEST(Sequencer, NonFiniteSamplesAreExcludedNeverAveraged) {
  const Session s = Simulate();
  Collected c;
  Sequencer seq(SequencerOptions{}, Collect(&c));
  const auto& ev = s.sim.events[3];
  // Two NaNs in a row (which the outlier gate alone would take for a real change).
  const int poisoned = ReplayCorrupting(s, &seq, ev, 1.0, 1.025, [](Sample* x) {
    x->acc_mps2->x() = std::numeric_limits<double>::quiet_NaN();
  });
  ASSERT_EQ(c.captured.size(), 26u);
  EXPECT_EQ(poisoned, 2);
  EXPECT_TRUE(c.captured[3].record->acc->mean.allFinite());
  EXPECT_EQ(c.captured[3].counts.flagged, 2);
}

// Schedule mode: a gap in the stream during a still segment must not let the rest of that
// segment count for the next pose.
TEST(Sequencer, InterruptionInAScheduledSegmentDoesNotShiftThePoses) {
  const Session s = Simulate();
  Collected c;
  Sequencer seq(SequencerOptions{}, Collect(&c));
  std::string error;
  ASSERT_TRUE(seq.SetSchedule(s.poses, &error));
  // 0.7 s without samples right after pose 2's record is complete (4.2 s into its 6 s still).
  const auto& ev = s.sim.events[2];
  for (const Sample& x : s.sim.samples) {
    const double t = x.t_host_ns * 1e-9;
    if (t > ev.t_s + 3.6 && t < ev.t_s + 4.3) continue;
    seq.Push(x);
  }
  seq.Finish(s.sim.samples.back().t_host_ns);
  ASSERT_EQ(c.captured.size(), 26u);
  for (std::size_t i = 0; i < 26; ++i) {
    const auto& e = s.sim.events[i];
    EXPECT_GE(c.captured[i].record->t_start_s, e.t_s - s.options.settle_s) << "pose " << i;
    EXPECT_LE(c.captured[i].record->t_end_s, e.dwell_end_s + 1e-9) << "pose " << i;
  }
  EXPECT_NE(c.events.back().reason.find("0 further still segments"), std::string::npos)
      << c.events.back().reason;
}

// A flagged sample right after a gap must not hide the gap.
TEST(Sequencer, FlaggedSampleAfterAGapStillInterruptsThePose) {
  const Session s = Simulate();
  Collected c;
  Sequencer seq(SequencerOptions{}, Collect(&c));
  const auto& ev = s.sim.events[4];
  Replay(s, &seq, [&](Sample* x) {
    const double t = x->t_host_ns * 1e-9;
    if (t > ev.t_s + 1.0 && t < ev.t_s + 1.3) return false;  // 30 samples lost
    if (t >= ev.t_s + 1.3 && t < ev.t_s + 1.31) x->flags |= kAccSaturated;
    return true;
  });
  ExpectOneRejection(c, 4, "the stream was interrupted (");
}

// Two bit errors that an 8-bit checksum misses can corrupt a sample's counter (or, for a device
// without one, its time stamp): a jump of thousands of samples, then the next sample continues the
// old sequence. That sample is dropped (counted as flagged), not taken for an interruption; a
// real gap, after which the stream continues from the jump, still interrupts the pose.
TEST(Sequencer, CorruptedCounterOrTimeStampIsNotAnInterruption) {
  const Session s = Simulate();
  for (const bool by_clock : {false, true}) {
    SCOPED_TRACE(by_clock ? "device clock" : "counter");
    Collected c;
    Sequencer seq(SequencerOptions{}, Collect(&c));
    int corrupted = 0;
    const auto middle = [&](int pose, const Sample& x) {
      const auto& ev = s.sim.events[pose];
      const double t = x.t_host_ns * 1e-9;
      return t >= 0.5 * (ev.t_s + ev.dwell_end_s) && t < 0.5 * (ev.t_s + ev.dwell_end_s) + 0.01;
    };
    Replay(s, &seq, [&](Sample* x) {
      if (by_clock) x->counter.reset();
      const double t = x->t_host_ns * 1e-9;
      if (middle(5, *x) || middle(9, *x)) {
        ++corrupted;
        const std::uint32_t bit = middle(5, *x) ? 0x4000 : 0x0100;
        if (by_clock) {
          *x->t_device_s += (middle(5, *x) ? 1.0 : -1.0) * bit / s.options.rate_hz;
        } else {
          *x->counter ^= bit;
        }
      }
      // Pose 13: 30 samples really lost.
      const auto& ev = s.sim.events[13];
      return !(t > ev.t_s + 1.0 && t < ev.t_s + 1.3);
    });
    ASSERT_EQ(corrupted, 2);
    ExpectOneRejection(c, 13, "the stream was interrupted (");
    ASSERT_EQ(c.captured.size(), 25u);
    for (const auto& e : c.captured) {
      const std::int64_t flagged = e.index == 5 || e.index == 9 ? 1 : 0;
      EXPECT_EQ(e.counts.flagged, flagged) << "pose " << e.index;
      EXPECT_EQ(e.counts.lost, 0) << "pose " << e.index;
    }
    EXPECT_EQ(seq.totals().flagged, 2);
    EXPECT_NEAR(static_cast<double>(seq.totals().lost), 30.0, 1.0);  // pose 13's gap only
  }
}

}  // namespace
}  // namespace turncal
