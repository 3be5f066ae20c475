// The pipeline's Monte Carlo (montecarlo/pipeline_montecarlo.h, `turncal montecarlo
// --pipeline`): options it refuses, and a few sessions as bytes through the station whose
// z-scores have a plausible spread. The spread itself is measured over 200 sessions per row in
// docs/ACCURACY.md; here only that the engine scores what the station estimates.
#include "montecarlo/pipeline_montecarlo.h"

#include <gtest/gtest.h>

#include <cmath>

namespace turncal::montecarlo {
namespace {

TEST(PipelineMonteCarlo, UnknownOptionsAreRefusedBeforeAnyRun) {
  PipelineMonteCarloOptions o;
  o.runs = 2;
  o.protocol = "nmea";
  PipelineMonteCarloSummary s = RunPipelineMonteCarlo(o);
  EXPECT_TRUE(s.bad_options);
  EXPECT_EQ(s.error, "unknown protocol 'nmea'");
  EXPECT_TRUE(s.runs.empty());
  o.protocol = "mip";
  o.sensor_class = "military";
  s = RunPipelineMonteCarlo(o);
  EXPECT_TRUE(s.bad_options);
  EXPECT_EQ(s.error, "unknown class 'military'");
  o.sensor_class = "industrial";
  o.model = "accel99";
  s = RunPipelineMonteCarlo(o);
  EXPECT_TRUE(s.bad_options);
  EXPECT_NE(s.error.find("accel99"), std::string::npos) << s.error;
}

// Four sessions of accel13 (an Xbus device at 100 Hz, the default plan, shuffled) on two
// threads: every run gives an estimate with a finite z for each of the 13 parameters, the runs
// keep their seeds' order whichever thread ran them, the gate passed, and the 52 z-scores have
// the spread of an honest sigma: their RMS is within [0.5, 1.6] (chi^2 with ~52 degrees of
// freedom, fewer for the correlated parameters of one run: outside with P < 1e-3), none beyond
// 5 sigma.
TEST(PipelineMonteCarlo, AFewSessionsThroughTheStationGiveHonestZScores) {
  PipelineMonteCarloOptions o;
  o.model = "accel13";
  o.protocol = "xbus";
  o.plan = "shuffled";
  o.runs = 4;
  o.jobs = 2;
  o.seed = 3;
  int progress_calls = 0, last = 0;
  o.progress = [&](int finished) {
    ++progress_calls;
    EXPECT_GT(finished, last);
    last = finished;
  };
  const PipelineMonteCarloSummary s = RunPipelineMonteCarlo(o);
  ASSERT_TRUE(s.error.empty()) << s.error;
  ASSERT_EQ(s.runs.size(), 4u);
  EXPECT_EQ(s.solved, 4) << s.first_error;
  EXPECT_EQ(progress_calls, 4);
  ASSERT_EQ(s.parameters.size(), 13u);
  double sum_sq = 0;
  int count = 0;
  for (std::size_t r = 0; r < s.runs.size(); ++r) {
    const PipelineRun& run = s.runs[r];
    EXPECT_EQ(run.seed, 3 * 1000003 + r);
    ASSERT_TRUE(run.ok) << run.error;
    ASSERT_EQ(run.z.size(), 13);
    EXPECT_LT(run.z.cwiseAbs().maxCoeff(), 5.0);
    EXPECT_GT(run.poses, 20);
    EXPECT_GT(run.session_s, 0.0);
    EXPECT_GE(run.p_value, 0.0);
    EXPECT_LE(run.p_value, 1.0);
    sum_sq += run.z.squaredNorm();
    count += 13;
  }
  const double rms = std::sqrt(sum_sq / count);
  EXPECT_GT(rms, 0.5);
  EXPECT_LT(rms, 1.6);
  EXPECT_EQ(s.z.runs(), 4);
  EXPECT_GE(s.ks.p, 0.0);
  EXPECT_LE(s.ks.p, 1.0);
  EXPECT_EQ(s.gate_pass, 4);
}

// Issue 38: a fixture of 4 units (the four mounts) replayed as one capture through one station:
// every unit of every session is scored against its own truth, its first activation its own,
// with the spread of an honest sigma (RMS within [0.5, 1.6] over 2 x 4 x 13 z-scores, none
// beyond 5 sigma); a fixture in a chamber is refused.
TEST(PipelineMonteCarlo, AFixtureOfFourUnitsIsScoredUnitByUnit) {
  PipelineMonteCarloOptions o;
  o.model = "accel13";
  o.protocol = "mip";
  o.runs = 2;
  o.jobs = 2;
  o.seed = 38;
  o.units = 4;
  const PipelineMonteCarloSummary s = RunPipelineMonteCarlo(o);
  ASSERT_TRUE(s.error.empty()) << s.error;
  ASSERT_EQ(s.runs.size(), 8u);
  EXPECT_EQ(s.solved, 8) << s.first_error;
  ASSERT_EQ(s.unit_z.size(), 4u);
  EXPECT_EQ(s.unit_mounts[1], "-y+x+z");
  double sum_sq = 0;
  for (std::size_t r = 0; r < s.runs.size(); ++r) {
    const PipelineRun& run = s.runs[r];
    EXPECT_EQ(run.unit, static_cast<int>(r % 4));
    ASSERT_TRUE(run.ok) << run.error;
    EXPECT_LT(run.z.cwiseAbs().maxCoeff(), 5.0) << "unit " << run.unit;
    EXPECT_GT(run.gate_poses, 5) << "unit " << run.unit;
    sum_sq += run.z.squaredNorm();
  }
  const double rms = std::sqrt(sum_sq / (8 * 13));
  EXPECT_GT(rms, 0.5);
  EXPECT_LT(rms, 1.6);
  for (const auto& u : s.unit_z) EXPECT_EQ(u.runs(), 2);
  o.chamber = "0; ramp 40 4 300";
  o.model = "mag13";
  const PipelineMonteCarloSummary refused = RunPipelineMonteCarlo(o);
  EXPECT_TRUE(refused.bad_options);
  EXPECT_EQ(refused.error, "--units: a fixture is not simulated in a chamber");
}

// In a climate chamber (issue 36): three sessions of mag13 through a 0 -> 40 degC ramp, the station
// calibrating mag13@T with the truth's orders; every run scores the 31 coefficients and the 13
// parameters at the 3 default held-out temperatures (the ramp's quarter points), with the spread
// of an honest sigma (RMS within [0.5, 1.6], none beyond 5 sigma: 3 runs of ~70 correlated
// z-scores). A profile that does not parse and a model with a gauge are refused before any run.
TEST(PipelineMonteCarlo, InAChamberEveryCoefficientAndHeldOutValueIsScored) {
  PipelineMonteCarloOptions o;
  o.model = "mag13";
  o.sensor_class = "consumer";
  o.chamber = "0; ramp 40 4 300";
  o.thermal_orders = "truth";
  o.rate_hz = 100;
  o.dwell_s = 4.0;
  o.runs = 3;
  o.jobs = 2;
  const PipelineMonteCarloSummary s = RunPipelineMonteCarlo(o);
  ASSERT_TRUE(s.error.empty()) << s.error;
  EXPECT_EQ(s.solved, 3) << s.first_error;
  // mag13's truth: g (9) and b (3) quadratics, beta constant: 12 x 3 + 1 coefficients.
  ASSERT_EQ(s.parameters.size(), 37u + 3u * 13u);
  EXPECT_EQ(s.parameters[1], "g11*dT");
  EXPECT_EQ(s.parameters[37], "g11@10C");
  EXPECT_EQ(s.parameters.back(), "bz@30C");
  double sum_sq = 0;
  Eigen::Index count = 0;
  for (const PipelineRun& run : s.runs) {
    ASSERT_TRUE(run.ok) << run.error;
    EXPECT_EQ(run.poses, 144);
    EXPECT_LT(run.z.cwiseAbs().maxCoeff(), 5.0);
    sum_sq += run.z.squaredNorm();
    count += run.z.size();
  }
  const double rms = std::sqrt(sum_sq / static_cast<double>(count));
  EXPECT_GT(rms, 0.5);
  EXPECT_LT(rms, 1.6);

  o.chamber = "0; ramp forty";
  EXPECT_TRUE(RunPipelineMonteCarlo(o).bad_options);
  o.chamber = "0; ramp 40 4 300";
  o.model = "mag22";
  const PipelineMonteCarloSummary g = RunPipelineMonteCarlo(o);
  EXPECT_TRUE(g.bad_options);
  EXPECT_NE(g.error.find("gauge"), std::string::npos) << g.error;
}

}  // namespace
}  // namespace turncal::montecarlo
