// The simulated climate chamber and die temperature (sim/chamber.h).

#include "sim/chamber.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace turncal
