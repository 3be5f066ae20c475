// The sequencer tests' fixture (tests/core/sequencer*_test.cc, host_clock_test.cc,
// noise_meter_test.cc): the 26-pose cube session simulated (sim/session_sim.h), replayed into a
// Sequencer with its pose events as announcements, the events it emits collected.
#pragma once

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/planning/pose_designs.h"
#include "core/sequencing/host_clock.h"
#include "core/sequencing/sequencer.h"
#include "core/sequencing/triad_accumulator.h"
#include "sim/session_sim.h"
#include "sim/synthetic.h"
#include "tests/support/simulated_session.h"

namespace turncal {

using Session = SimulatedRun;

// The 26-pose cube session at 100 Hz; without bias wander unless asked, so the true mean of a
// window is the model's prediction exactly.
inline Session Simulate(bool wander = false, std::uint64_t seed = 7, double rate_hz = 100.0) {
  SessionSimOptions options;
  options.rate_hz = rate_hz;
  options.seed = seed;
  if (!wander) options.sensor.acc_bias_instability = options.sensor.mag_bias_instability = 0;
  return SimulateAccelMagSession(CubePoses26(), options);
}

struct Collected {
  std::vector<SequencerEvent> events;
  std::vector<SequencerEvent> captured, rejected, skipped;
};

inline Sequencer::Sink Collect(Collected* c) {
  return [c](const SequencerEvent& e) {
    c->events.push_back(e);
    if (e.kind == SequencerEventKind::kCaptured) c->captured.push_back(e);
    if (e.kind == SequencerEventKind::kRejected) c->rejected.push_back(e);
    if (e.kind == SequencerEventKind::kSegmentSkipped) c->skipped.push_back(e);
  };
}

// The uncalibrated pose check: nominal accelerometer, 5 degrees of tolerance.
inline PosePredictor NominalAccPredictor(const MeasurementModel& accel) {
  return [&accel](const TablePose& pose, int triad) -> std::optional<TriadPrediction> {
    if (triad != kTriadAcc) return std::nullopt;
    return NominalPrediction(accel, pose, 5 * M_PI / 180, 1e-6);
  };
}

inline std::int64_t Ns(double t_s) { return static_cast<std::int64_t>(std::llround(t_s * 1e9)); }

// The controller's announcement of a simulated pose event, at `t_s` (host seconds).
inline Announcement AnnouncementOf(const SessionPoseEvent& ev, double t_s) {
  Announcement a;
  a.index = ev.index;
  a.pose = ev.pose;
  a.t_host_ns = Ns(t_s);
  return a;
}

// Feeds the session with its pose events as announcements (optionally `early` seconds early for
// one pose), through `transform` for each sample.
template <typename Transform>
void Replay(const Session& s, Sequencer* seq, Transform transform, int early_index = -1,
            double early_s = 0.0) {
  std::size_t next = 0;
  auto announce_time = [&](std::size_t i) {
    return s.sim.events[i].t_s - (static_cast<int>(i) == early_index ? early_s : 0.0);
  };
  for (const Sample& raw : s.sim.samples) {
    while (next < s.sim.events.size() && Ns(announce_time(next)) <= raw.t_host_ns) {
      std::string error;
      EXPECT_TRUE(seq->Announce(AnnouncementOf(s.sim.events[next], announce_time(next)), &error))
          << error;
      ++next;
    }
    Sample x = raw;
    if (transform(&x)) seq->Push(x);
  }
  seq->Finish(s.sim.samples.back().t_host_ns);
}

inline void Replay(const Session& s, Sequencer* seq) {
  Replay(s, seq, [](Sample*) { return true; });
}

// The session's one rejection: pose `index` (-1: any pose), for a reason that contains `reason`.
// (Its ASSERT ends only this function: callers do not look at c.rejected afterwards.)
inline void ExpectOneRejection(const Collected& c, int index, const std::string& reason) {
  ASSERT_EQ(c.rejected.size(), 1u);
  if (index >= 0) {
    EXPECT_EQ(c.rejected[0].index, index);
  }
  EXPECT_NE(c.rejected[0].reason.find(reason), std::string::npos) << c.rejected[0].reason;
}

// The per-sample noise sigma of the accelerometer in this session.
inline double AccSigma(const Session& s) {
  return s.options.sensor.acc_noise_density * std::sqrt(s.options.rate_hz / 2.0);
}

}  // namespace turncal
