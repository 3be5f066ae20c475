// The simulated climate chamber and die temperature (sim/chamber.h).

#include "sim/chamber.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

namespace turncal {
namespace {

TEST(ChamberProfile, ParsesTheTextAndGivesItBack) {
  ChamberProfile p;
  std::string error;
  ASSERT_TRUE(ChamberProfile::Parse("25; ramp -20 2 1200; soak 70 600; ramp 25 1.5", &p, &error))
      << error;
  EXPECT_EQ(p.start_c, 25.0);
  ASSERT_EQ(p.steps.size(), 3u);
  EXPECT_EQ(p.steps[0].setpoint_c, -20.0);
  EXPECT_EQ(p.steps[0].rate_c_per_min, 2.0);
  EXPECT_EQ(p.steps[0].hold_s, 1200.0);
  EXPECT_EQ(p.steps[1].rate_c_per_min, 0.0);
  EXPECT_EQ(p.steps[2].hold_s, 0.0);
  EXPECT_EQ(p.ToString(), "25; ramp -20 2 1200; soak 70 600; ramp 25 1.5 0");
  ChamberProfile again;
  ASSERT_TRUE(ChamberProfile::Parse(p.ToString(), &again, &error)) << error;
  EXPECT_EQ(again.ToString(), p.ToString());
  // 45 degC at 2 degC/min is 1350 s, then 1200; the soak 600; 45 degC at 1.5 degC/min 1800 s.
  EXPECT_DOUBLE_EQ(p.duration_s(), 1350.0 + 1200.0 + 600.0 + 1800.0);
}

TEST(ChamberProfile, RefusesMalformedTextWithTheStep) {
  ChamberProfile p;
  std::string error;
  EXPECT_FALSE(ChamberProfile::Parse("", &p, &error));
  EXPECT_FALSE(ChamberProfile::Parse("warm", &p, &error));
  EXPECT_FALSE(ChamberProfile::Parse("25; bake 80 100", &p, &error));
  EXPECT_NE(error.find("step 1"), std::string::npos) << error;
  EXPECT_FALSE(ChamberProfile::Parse("25; soak 40 100; ramp 80 0", &p, &error));
  EXPECT_NE(error.find("step 2"), std::string::npos) << error;
  EXPECT_FALSE(ChamberProfile::Parse("25; soak 400 100", &p, &error));
  EXPECT_NE(error.find("-70 .. 180"), std::string::npos) << error;
  EXPECT_FALSE(ChamberProfile::Parse("25; soak 40 100 7", &p, &error));
  EXPECT_NE(error.find("unexpected '7'"), std::string::npos) << error;
}

TEST(ChamberProfile, TheAirFollowsRampsAndHolds) {
  const ChamberProfile p = ChamberProfile::Soaks(20.0, {40.0, 0.0}, 2.0, 300.0);
  EXPECT_DOUBLE_EQ(p.AirAt(-5.0), 20.0);
  EXPECT_DOUBLE_EQ(p.AirAt(0.0), 20.0);
  EXPECT_DOUBLE_EQ(p.AirAt(300.0), 30.0);          // half way up at 2 degC/min
  EXPECT_DOUBLE_EQ(p.AirAt(700.0), 40.0);          // holding
  EXPECT_DOUBLE_EQ(p.AirAt(900.0 + 600.0), 20.0);  // half way down
  EXPECT_DOUBLE_EQ(p.AirAt(1e6), 0.0);
  EXPECT_DOUBLE_EQ(p.duration_s(), 600.0 + 300.0 + 1200.0 + 300.0);
}

// The die settles to the air plus the self-heating after a step, and lags a steady ramp by
// rate x tau (the first-order lag's steady state).
TEST(DieTemperature, LagsTheAirByItsTimeConstant) {
  DieThermal die;
  die.tau_s = 300.0;
  die.self_heating_c = 0.0;
  const ChamberProfile step = ChamberProfile::Soaks(20.0, {60.0}, 0.0, 3600.0);
  DieTemperature d(step, die);
  double t = 0.0;
  for (; t < 300.0; t += 0.01) d.Advance(t);
  EXPECT_NEAR(d.Advance(300.0), 20.0 + 40.0 * (1.0 - std::exp(-1.0)), 0.05);
  for (; t < 3000.0; t += 0.01) d.Advance(t);
  EXPECT_NEAR(d.Advance(3000.0), 60.0, 0.01);

  const ChamberProfile ramp = ChamberProfile::Soaks(-20.0, {80.0}, 2.0, 0.0);
  DieTemperature r(ramp, die);
  for (t = 0.0; t < 2400.0; t += 0.01) r.Advance(t);
  EXPECT_NEAR(r.Advance(2400.0), ramp.AirAt(2400.0) - 2.0 / 60.0 * 300.0, 0.05);

  DieThermal heated = die;
  heated.self_heating_c = 3.0;
  heated.self_heating_tau_s = 600.0;
  const ChamberProfile still = ChamberProfile::Soaks(25.0, {25.0}, 0.0, 1e4);
  DieTemperature h(still, heated);
  for (t = 0.0; t < 8000.0; t += 0.05) h.Advance(t);
  EXPECT_NEAR(h.Advance(8000.0), 28.0, 0.01);
}

TEST(DieTemperature, ReportsInTheDevicesSteps) {
  DieThermal die;
  die.quantum_c = 1.0;
  const ChamberProfile p;
  DieTemperature d(p, die);
  EXPECT_EQ(d.Reported(24.4), 24.0);
  EXPECT_EQ(d.Reported(-3.6), -4.0);
  die.quantum_c = 0.0;
  DieTemperature f(p, die);
  EXPECT_EQ(f.Reported(24.4), 24.4);
}

// Hysteresis as a play of width H: rising, the parameters are at the die minus H / 2; at the
// turn they stand still until the die has fallen by H; falling, at the die plus H / 2. Without
// hysteresis they are at the die exactly.
TEST(DieTemperature, HysteresisIsAPlayBetweenTheDieAndTheParameters) {
  DieThermal die;
  die.tau_s = 30.0;
  die.self_heating_c = 0.0;
  die.hysteresis_c = 2.0;
  ChamberProfile p;
  ASSERT_TRUE(ChamberProfile::Parse("0; ramp 40 4 600; ramp 0 4 600", &p, nullptr));
  DieTemperature d(p, die);
  DieThermal plain = die;
  plain.hysteresis_c = 0.0;
  DieTemperature q(p, plain);
  double t = 0.0, top_die = -1e9, top_param = -1e9;
  for (; t < 400.0; t += 0.05) {
    const double die_c = d.Advance(t);
    EXPECT_EQ(q.Advance(t), die_c);
    EXPECT_EQ(q.parameter_c(), die_c);
    EXPECT_LE(std::abs(d.parameter_c() - die_c), 1.0 + 1e-12);
  }
  const double rising_die_c = d.Advance(t);  // before parameter_c(): arguments have no order
  EXPECT_NEAR(d.parameter_c(), rising_die_c - 1.0, 1e-9);  // rising: H / 2 below
  // The die settles at 40 (the ramp down starts at 1200 s), then falls: the parameters hold at
  // the top's 39 until the die is at 38, then follow it 1 above.
  int held = 0;
  for (; t < 1500.0; t += 0.05) {
    const double die_c = d.Advance(t);
    top_die = std::max(top_die, die_c);
    top_param = std::max(top_param, d.parameter_c());
    if (t > 1200.0 && die_c > top_die - 2.0 + 1e-6) {
      EXPECT_NEAR(d.parameter_c(), top_param, 1e-9) << t;
      ++held;
    }
  }
  EXPECT_GT(held, 100);  // some seconds of the fall
  EXPECT_NEAR(top_param, top_die - 1.0, 1e-6);
  const double falling_die_c = d.Advance(t);
  EXPECT_LT(falling_die_c, 30.0);
  EXPECT_NEAR(d.parameter_c(), falling_die_c + 1.0, 1e-9);  // falling: H / 2 above
  die.hysteresis_c = -1.0;
  std::string error;
  EXPECT_FALSE(die.IsValid(&error));
  EXPECT_NE(error.find("hysteresis"), std::string::npos) << error;
}

}  // namespace
}  // namespace turncal
