// The calibration over temperature's Monte Carlo (montecarlo/thermal_montecarlo.h): a short run's
// statistics, its comparison with offset-only polynomials, and its refusals.

#include "montecarlo/thermal_montecarlo.h"

#include <gtest/gtest.h>

#include <cmath>

namespace turncal::montecarlo {
namespace {

// 30 consumer accelerometers: every run solves; over all coefficients and held-out values the z
// spread is 1 within its sampling error (750 and 1170 correlated z's: about +-0.05, checked at
// +-0.15); and because the consumer class's scale factors move by 0.03 %/K, offset-only cubics
// leave several times the error of the full model in the corrected output.
TEST(ThermalMonteCarlo, ConsumerAccelerometersAreHonestAndBeatOffsetOnlyCubics) {
  ThermalMonteCarloOptions o;
  o.sensor_class = "consumer";
  o.runs = 30;
  o.jobs = 2;
  const ThermalMonteCarloSummary s = RunThermalMonteCarlo(o);
  ASSERT_TRUE(s.error.empty()) << s.error;
  EXPECT_EQ(s.solved, 30) << s.first_error;
  ASSERT_EQ(s.z.runs(), 30);
  ASSERT_EQ(s.held_out.size(), 4u * 13u);  // four midpoints between five soaks
  EXPECT_EQ(s.held_out[13], "Sx at 15 degC");
  auto pooled = [](const ZScoreSummary& z) {
    const Eigen::VectorXd m = z.Mean(), sd = z.Std();
    // Pooled second moment over the parameters.
    return std::sqrt((sd.array().square() + m.array().square()).mean());
  };
  EXPECT_NEAR(pooled(s.z), 1.0, 0.15);
  EXPECT_NEAR(pooled(s.z_held), 1.0, 0.15);
  EXPECT_GT(s.ks.p, 1e-3);
  EXPECT_GT(s.rms_error_offset_only, 3.0 * s.rms_error_full)
      << s.rms_error_offset_only << " vs " << s.rms_error_full;
  EXPECT_EQ(s.unit, "m/s^2");
}

TEST(ThermalMonteCarlo, RefusesWhatCannotRun) {
  ThermalMonteCarloOptions o;
  o.runs = 2;
  o.model = "accel99";
  EXPECT_FALSE(RunThermalMonteCarlo(o).error.empty());
  o.model = "accel13";
  o.sensor_class = "military";
  EXPECT_FALSE(RunThermalMonteCarlo(o).error.empty());
  o.sensor_class = "industrial";
  o.soaks_c = {25.0};
  EXPECT_NE(RunThermalMonteCarlo(o).error.find("two soak"), std::string::npos);
  o.soaks_c = {0.0, 40.0};
  o.orders = "some";
  EXPECT_NE(RunThermalMonteCarlo(o).error.find("truth, chosen or full"), std::string::npos);
}

}  // namespace
}  // namespace turncal::montecarlo
