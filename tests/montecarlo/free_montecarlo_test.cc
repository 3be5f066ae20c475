// The free-mode Monte Carlo (montecarlo/free_montecarlo.h, `turncal free-montecarlo`): gate
// reasons counted alike, options it refuses, and a few tumbles as bytes through the free
// station whose z-scores have a plausible spread (the spread over 200 tumbles is
// docs/ACCURACY.md's).
#include "montecarlo/free_montecarlo.h"

#include <gtest/gtest.h>

#include <cmath>

namespace turncal::montecarlo {
namespace {

TEST(GateReasonKind, NumbersBecomeOneMarkEach) {
  EXPECT_EQ(GateReasonKind("sigma of bx 1.5e-3 m/s^2 above its tolerance 2E-4"),
            "sigma of bx # m/s^# above its tolerance #");
  EXPECT_EQ(GateReasonKind("coverage 12 of 576 bins (.5 %)"), "coverage # of # bins (# %)");
  EXPECT_EQ(GateReasonKind("accel9 rank 8"), "accel# rank #");
  EXPECT_EQ(GateReasonKind("no numbers here."), "no numbers here.");
  EXPECT_EQ(GateReasonKind("1e-5e"), "#e");
}

TEST(FreeMonteCarlo, OptionsThatCannotWorkAreRefused) {
  FreeMonteCarloOptions o;
  o.runs = 2;
  o.protocol = "nmea";
  EXPECT_EQ(RunFreeMonteCarlo(o).error, "unknown protocol 'nmea'");
  o.protocol = "mip";
  o.model = "magsphere";
  EXPECT_EQ(RunFreeMonteCarlo(o).error, "the simulator's magnetometer is an ellipsoid");
  o.model = "accel13";  // a turntable model, no free one
  EXPECT_FALSE(RunFreeMonteCarlo(o).error.empty());
}

// Three tumbles of 20 orientations for accel9 on an Xbus device (100 Hz): each gives an estimate
// the gate judged, z finite for all 9 parameters, none beyond 5 sigma, and the 27 z-scores' RMS
// within [0.4, 1.8] (chi^2 with at most 27 degrees of freedom: outside with P < 1e-3).
TEST(FreeMonteCarlo, AFewTumblesThroughFreeModeGiveHonestZScores) {
  FreeMonteCarloOptions o;
  o.model = "accel9";
  o.protocol = "xbus";
  o.runs = 3;
  o.jobs = 2;
  o.orientations = 20;
  int calls = 0;
  o.on_run = [&](int run, const FreeRun& r, int scored, const std::vector<std::string>& names) {
    ++calls;
    EXPECT_GE(run, 0);
    EXPECT_LE(scored, 3);
    EXPECT_EQ(static_cast<Eigen::Index>(names.size()), r.z.size());
  };
  const FreeMonteCarloSummary s = RunFreeMonteCarlo(o);
  ASSERT_TRUE(s.error.empty()) << s.error;
  EXPECT_EQ(s.solved, 3) << s.first_error;
  EXPECT_EQ(calls, 3);
  EXPECT_EQ(s.gated, 3);
  ASSERT_EQ(s.parameters.size(), 9u);
  double sum_sq = 0;
  for (const FreeRun& r : s.runs) {
    ASSERT_TRUE(r.ok) << r.error;
    EXPECT_GT(r.intervals, 10);
    EXPECT_LT(r.z.cwiseAbs().maxCoeff(), 5.0);
    sum_sq += r.z.squaredNorm();
  }
  const double rms = std::sqrt(sum_sq / 27);
  EXPECT_GT(rms, 0.4);
  EXPECT_LT(rms, 1.8);
  ASSERT_EQ(s.p_value_deciles.size(), 10u);
  int deciles = 0;
  for (int d : s.p_value_deciles) deciles += d;
  EXPECT_EQ(deciles, 3);
}

}  // namespace
}  // namespace turncal::montecarlo
