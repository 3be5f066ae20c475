// Planning over temperature (montecarlo/thermal_plan.h) on a small range and a quick die, so that
// it runs in seconds: the classic procedure's time holds at least its soaks and its poses, a ramp's
// at least the ramp, the plan is quicker than the classic procedure, a seed gives the same times,
// the simulated wander is the one the calibrator's drift model has (chi^2 honest), and what cannot
// be planned is refused with the reason.

#include "montecarlo/thermal_plan.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace turncal::montecarlo {
namespace {

ThermalPlanOptions Small() {
  ThermalPlanOptions o;
  o.model = "mag13";
  o.sensor_class = "industrial";
  o.t_lo_c = 0.0;
  o.t_hi_c = 20.0;
  o.die_tau_s = 60.0;
  o.plateaus = 3;
  o.ramp_rates_c_per_min = {1.0, 2.0};
  o.runs = 2;
  o.jobs = 2;
  return o;
}

TEST(ThermalPlan, TheRampIsQuickerThanTheClassicSoaksAndBothHoldWhatTheyMust) {
  const ThermalPlanOptions o = Small();
  const ThermalPlan plan = PlanOverTemperature(o);
  ASSERT_TRUE(plan.error.empty()) << plan.error;
  ASSERT_GT(plan.pose_s, o.dwell_s);
  ASSERT_EQ(plan.classic.failures(), 0) << plan.classic.last_reason;
  // The classic procedure: the two ramps between the plateaus at the chamber's rate, the die's
  // settling after each (the soak test's window at least), and its poses.
  const double ramps_s = (o.t_hi_c - o.t_lo_c) / o.chamber_max_rate_c_per_min * 60.0;
  const double poses_s = 26.0 * plan.classic.cubes * o.plateaus * plan.pose_s;
  EXPECT_GE(plan.classic.min_seconds(), ramps_s + 2 * o.soak_window_s + 0.8 * poses_s);
  ASSERT_EQ(plan.ramps.size(), 2u);
  ASSERT_GE(plan.chosen, 0);
  const ThermalProcedureOutcome& chosen = plan.ramps[static_cast<std::size_t>(plan.chosen)];
  EXPECT_EQ(chosen.failures(), 0);
  // A ramp takes at least the ramp itself, and the plan less than the classic procedure.
  EXPECT_GE(chosen.min_seconds(), (o.t_hi_c - o.t_lo_c) / chosen.rate_c_per_min * 60.0);
  EXPECT_LT(chosen.max_seconds(), plan.classic.max_seconds());
  EXPECT_EQ(chosen.chamber.rfind("0; ramp 20 ", 0), 0u) << chosen.chamber;
  // The ramps were tried fastest first.
  EXPECT_EQ(plan.ramps[0].rate_c_per_min, 2.0);
}

TEST(ThermalPlan, ASeedGivesTheSameTimes) {
  const ThermalPlan a = PlanOverTemperature(Small());
  ThermalPlanOptions o = Small();
  o.jobs = 1;
  const ThermalPlan b = PlanOverTemperature(o);
  EXPECT_EQ(a.classic.seconds, b.classic.seconds);
  ASSERT_EQ(a.ramps.size(), b.ramps.size());
  for (std::size_t k = 0; k < a.ramps.size(); ++k)
    EXPECT_EQ(a.ramps[k].seconds, b.ramps[k].seconds);
}

// The planner's devices wander as the class says and the calibrator's drift model has it (the mean
// over each dwell): the last fit's chi^2 p-values are uniform. Before the wander was averaged over
// the dwell (it was the value at the dwell's middle), the consumer magnetometer's chi^2 / dof was
// 1.07-1.18 along a -20..60 degC ramp, p < 0.05 in 12 of 12 runs, and a quarter of the devices
// failed the gate on it. 12 runs: the median p below 0.05 would take 6 of 12 uniform draws
// there (probability 2e-5); none below 1e-3 has probability 0.99.
TEST(ThermalPlan, TheSimulatedWanderIsTheDriftModelsChiSquareIsHonest) {
  ThermalPlanOptions o;
  o.model = "mag13";
  o.sensor_class = "consumer";
  o.t_lo_c = -20.0;
  o.t_hi_c = 60.0;
  o.ramp_rates_c_per_min = {2.0};
  o.runs = 12;
  o.jobs = 2;
  const ThermalPlan plan = PlanOverTemperature(o);
  ASSERT_TRUE(plan.error.empty()) << plan.error;
  ASSERT_EQ(plan.ramps.size(), 1u);
  std::vector<double> p = plan.ramps[0].chi2_p;
  ASSERT_EQ(p.size(), 12u);
  for (double v : p) {
    ASSERT_TRUE(std::isfinite(v));
    EXPECT_GT(v, 1e-3);
  }
  std::sort(p.begin(), p.end());
  EXPECT_GT(0.5 * (p[5] + p[6]), 0.05);
  EXPECT_EQ(plan.ramps[0].failures(), 0);
}

// A ramp with the cube at each end: the cube at the low end before the chamber moves (its time
// and poses come first), the chamber's profile holds there, and the ramp still passes.
TEST(ThermalPlan, ARampWithCubesAtTheEndsTakesThemFirstAtTheLowEnd) {
  ThermalPlanOptions o = Small();
  o.ramp_rates_c_per_min = {2.0};
  o.end_cubes = {1};
  const ThermalPlan plan = PlanOverTemperature(o);
  ASSERT_TRUE(plan.error.empty()) << plan.error;
  ASSERT_EQ(plan.ramps.size(), 1u);
  const ThermalProcedureOutcome& r = plan.ramps[0];
  EXPECT_EQ(r.end_cubes, 1);
  ASSERT_EQ(r.failures(), 0) << r.last_reason;
  const double ramp_s = (o.t_hi_c - o.t_lo_c) / r.rate_c_per_min * 60.0;
  EXPECT_GE(r.min_seconds(), ramp_s + 26.0 * plan.pose_s);
  for (int poses : r.poses) EXPECT_GT(poses, 26);
  EXPECT_EQ(r.chamber.rfind("0; soak 0 ", 0), 0u) << r.chamber;
  EXPECT_NE(r.name.find("1 cube at each end"), std::string::npos) << r.name;
}

TEST(ThermalPlan, WhatCannotBePlannedIsRefusedWithTheReason) {
  ThermalPlanOptions o = Small();
  o.t_hi_c = 5.0;
  EXPECT_NE(PlanOverTemperature(o).error.find("at least 10 degC"), std::string::npos);
  o = Small();
  o.ramp_rates_c_per_min = {3.0};
  EXPECT_NE(PlanOverTemperature(o).error.find("at most the chamber's 2"), std::string::npos);
  o = Small();
  o.end_cubes = {-1};
  EXPECT_NE(PlanOverTemperature(o).error.find("end cubes -1"), std::string::npos);
  o = Small();
  o.model = "gyro12";
  EXPECT_NE(PlanOverTemperature(o).error.find("rate segments"), std::string::npos);
  o = Small();
  o.sensor_class = "hobby";
  EXPECT_NE(PlanOverTemperature(o).error.find("unknown sensor class"), std::string::npos);
}

}  // namespace
}  // namespace turncal::montecarlo
