// Calibration over temperature (core/estimation/thermal_calibrator.h): pose records at several
// temperatures of a sensor whose parameters are polynomials in T (sim/thermal_truth.h), in memory.
// Tolerances from the estimate's own covariance (3.5-4 sigma per value; the z-scores' spread
// against its sampling error over the runs).

#include "core/estimation/thermal_calibrator.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>

#include "core/planning/pose_designs.h"
#include "sim/synthetic.h"
#include "sim/thermal_truth.h"

namespace turncal {
namespace {

struct ThermalRun {
  std::unique_ptr<MeasurementModel> model;
  ThermalTruth truth;
  std::vector<PoseRecord> records;
  CalibratorOptions options;
};

// The 26 cube poses at each temperature, 5 s each, in time order; the record's temperature is
// the one the truth is evaluated at.
ThermalRun Simulate(const std::string& name, const SensorClass& sensor,
                    const std::vector<double>& temps_c, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  ThermalRun run;
  std::string error;
  run.model = MakeModel(name, ModelContext{}, &error);
  EXPECT_NE(run.model, nullptr) << error;
  run.truth = DrawThermalTruth(*run.model, sensor, 25.0, &rng);
  run.options = OptionsForClass(*run.model, sensor);
  double t_s = 0.0;
  for (double temp_c : temps_c) {
    for (const TablePose& pose : CubePoses26()) {
      PoseRecord r = SimulateRecord(*run.model, run.truth.ThetaAt(temp_c), pose, sensor, 5.0, &rng);
      r.temp_c = temp_c;
      r.t_start_s = t_s;
      r.t_end_s = t_s + 5.0;
      t_s += 10.0;
      run.records.push_back(r);
    }
  }
  return run;
}

const std::vector<double> kFiveSoaks = {-20.0, 5.0, 25.0, 45.0, 70.0};

TEST(ThermalBasis, DesignEvaluatesEachParametersPolynomial) {
  ThermalBasis b;
  b.t0_c = 20.0;
  b.scale_c = 10.0;
  b.orders = {0, 2, 1};
  ASSERT_EQ(b.num_coefficients(), 6);
  EXPECT_EQ(b.index(1, 2), 3);
  EXPECT_EQ(b.index(2, 0), 4);
  Eigen::VectorXd c(6);
  c << 1.0, 2.0, 3.0, 4.0, 5.0, 6.0;
  // u = (40 - 20) / 10 = 2: [1, 2 + 3*2 + 4*4, 5 + 6*2].
  const Eigen::VectorXd theta = b.Theta(c, 40.0);
  EXPECT_DOUBLE_EQ(theta[0], 1.0);
  EXPECT_DOUBLE_EQ(theta[1], 24.0);
  EXPECT_DOUBLE_EQ(theta[2], 17.0);
  // The unscaled basis gives the same values with coefficients per degree C^j.
  const Eigen::VectorXd unscaled = b.ToUnscaled().asDiagonal() * c;
  const Eigen::VectorXd same = b.Unscaled().Theta(unscaled, 40.0);
  EXPECT_NEAR((same - theta).norm(), 0.0, 1e-12);
  const std::vector<ParameterInfo> names = {{"a"}, {"bx"}, {"c"}};
  EXPECT_EQ(b.CoefficientName(names, 1), "bx");
  EXPECT_EQ(b.CoefficientName(names, 2), "bx*dT");
  EXPECT_EQ(b.CoefficientName(names, 3), "bx*dT^2");
  EXPECT_EQ(b.CoefficientName(names, 5), "c*dT");
}

// With the truth's orders given, every coefficient and every parameter at a temperature between
// the soaks lies within 4 sigma of the truth, and chi^2 fits.
TEST(ThermalCalibrator, GivenOrdersRecoverEveryCoefficientWithinItsSigma) {
  for (const char* name : {"accel13", "mag13"}) {
    for (const SensorClass& sensor : {IndustrialClass(), ConsumerClass()}) {
      SCOPED_TRACE(std::string(name) + " " + sensor.name);
      ThermalRun run = Simulate(name, sensor, kFiveSoaks, 7);
      ThermalOptions thermal;
      thermal.orders = run.truth.basis.orders;
      thermal.t0_c = 25.0;
      const ThermalEstimate est = CalibrateOverTemperature(run.options, run.records, thermal);
      ASSERT_TRUE(est.ok) << est.error;
      ASSERT_EQ(est.coefficients.size(), run.truth.coefficients.size());
      EXPECT_EQ(est.rank, est.coefficients.size());
      EXPECT_GT(est.p_value, 1e-4) << est.BriefReport();
      for (int j = 0; j < est.coefficients.size(); ++j) {
        EXPECT_LT(std::abs(est.coefficients[j] - run.truth.coefficients[j]), 4.0 * est.sigma[j])
            << est.coefficient_names[static_cast<std::size_t>(j)];
      }
      for (double t : {-5.0, 35.0, 60.0}) {
        const Eigen::VectorXd err = est.ThetaAt(t) - run.truth.ThetaAt(t);
        const Eigen::VectorXd sigma = est.SigmaAt(t);
        for (int p = 0; p < err.size(); ++p) {
          EXPECT_LT(std::abs(err[p]), 4.0 * sigma[p]) << est.parameters[p].name << " at " << t;
        }
      }
    }
  }
}

// With the class's drift as a process in time, the poses are whitened together in time order
// (generalised least squares); the records here have no drift, so every coefficient is within its
// (larger) sigma and chi^2 is small rather than large.
TEST(ThermalCalibrator, WithADriftModelThePosesAreWhitenedTogether) {
  ThermalRun run = Simulate("accel13", IndustrialClass(), kFiveSoaks, 21);
  const CalibratorOptions drift = DriftOptionsForClass(*run.model, IndustrialClass());
  ASSERT_TRUE(drift.drift.enabled());
  ThermalOptions thermal;
  thermal.orders = run.truth.basis.orders;
  thermal.t0_c = 25.0;
  const ThermalEstimate est = CalibrateOverTemperature(drift, run.records, thermal);
  ASSERT_TRUE(est.ok) << est.error;
  const ThermalEstimate independent = CalibrateOverTemperature(run.options, run.records, thermal);
  ASSERT_TRUE(independent.ok) << independent.error;
  for (int j = 0; j < est.coefficients.size(); ++j) {
    EXPECT_LT(std::abs(est.coefficients[j] - run.truth.coefficients[j]), 4.0 * est.sigma[j])
        << est.coefficient_names[static_cast<std::size_t>(j)];
  }
  // The drift correlates the biases across poses: their constant terms are less certain than with
  // independent poses.
  const int bx = est.basis.index(static_cast<int>(est.parameters.size()) - 3, 0);
  EXPECT_GT(est.sigma[bx], independent.sigma[bx]);
  EXPECT_EQ(est.residuals.size(), run.records.size());
}

// The orders chosen from the data: a parameter with no temperature dependence (the mounting,
// beta) keeps order 0; the consumer accelerometer's biases, whose slope is 1 mg/K over 90 K,
// get at least order 1; no parameter gets more than the soaks carry, and each says why.
TEST(ThermalCalibrator, OrdersAreChosenFromTheData) {
  ThermalRun run = Simulate("accel13", ConsumerClass(), kFiveSoaks, 11);
  const ThermalEstimate est = CalibrateOverTemperature(run.options, run.records, ThermalOptions{});
  ASSERT_TRUE(est.ok) << est.error;
  EXPECT_EQ(est.distinct_temperatures, 5);
  EXPECT_NEAR(est.basis.t0_c, 25.0, 1e-9);  // the middle of -20 .. 70
  for (const char* p : {"eps_x", "eps_y", "eps_z", "beta"}) EXPECT_EQ(est.order_of(p), 0) << p;
  for (const char* p : {"bx", "by", "bz"}) EXPECT_GE(est.order_of(p), 1) << est.BriefReport();
  ASSERT_EQ(est.order_reasons.size(), est.parameters.size());
  for (std::size_t p = 0; p < est.parameters.size(); ++p) {
    EXPECT_LE(est.basis.orders[p], 3);
    EXPECT_FALSE(est.order_reasons[p].empty());
  }
  EXPECT_GE(est.solves, 2);
  if (std::getenv("TURNCAL_THERMAL_DEBUG")) {
    std::printf("%s\n", est.BriefReport().c_str());
    for (auto& r : est.order_reasons) std::printf("%s\n", r.c_str());
  }
  // Chosen or not, every parameter at a held-out temperature is within 4 sigma of the truth.
  const Eigen::VectorXd err = est.ThetaAt(35.0) - run.truth.ThetaAt(35.0);
  const Eigen::VectorXd sigma = est.SigmaAt(35.0);
  for (int p = 0; p < err.size(); ++p) {
    EXPECT_LT(std::abs(err[p]), 4.0 * sigma[p]) << est.parameters[p].name << est.BriefReport();
  }
}

// Over repeated sensors, the z-scores of every coefficient (truth orders given) have unit spread:
// sigma is honest, not only small. 30 runs x 25 coefficients; the spread's sampling error over
// 750 correlated z's is about 0.03-0.05.
TEST(ThermalCalibrator, ZScoresOverRepeatedSensorsHaveUnitSpread) {
  double sum = 0.0, sum2 = 0.0;
  int n = 0;
  for (std::uint64_t seed = 100; seed < 130; ++seed) {
    ThermalRun run = Simulate("accel13", IndustrialClass(), {-10.0, 10.0, 30.0, 50.0}, seed);
    ThermalOptions thermal;
    thermal.orders = run.truth.basis.orders;
    thermal.t0_c = 25.0;
    const ThermalEstimate est = CalibrateOverTemperature(run.options, run.records, thermal);
    ASSERT_TRUE(est.ok) << est.error;
    for (int j = 0; j < est.coefficients.size(); ++j) {
      const double z = (est.coefficients[j] - run.truth.coefficients[j]) / est.sigma[j];
      sum += z;
      sum2 += z * z;
      ++n;
    }
  }
  const double mean = sum / n, std = std::sqrt(sum2 / n - mean * mean);
  EXPECT_LT(std::abs(mean), 0.15);
  EXPECT_GT(std, 0.85);
  EXPECT_LT(std, 1.15);
}

// One temperature: every order 0, with the reason, and no NaN; orders asked beyond what two
// temperatures carry are lowered to 1 with a warning.
TEST(ThermalCalibrator, TooFewTemperaturesLowerTheOrderAndSaySo) {
  ThermalRun one = Simulate("accel13", IndustrialClass(), {25.0}, 3);
  const ThermalEstimate flat = CalibrateOverTemperature(one.options, one.records, ThermalOptions{});
  ASSERT_TRUE(flat.ok) << flat.error;
  EXPECT_EQ(flat.distinct_temperatures, 1);
  EXPECT_EQ(flat.coefficients.size(), 13);
  EXPECT_TRUE(flat.coefficients.allFinite());
  EXPECT_TRUE(flat.SigmaAt(25.0).allFinite());
  EXPECT_NE(flat.order_reasons[0].find("1 distinct temperature"), std::string::npos)
      << flat.order_reasons[0];

  ThermalRun two = Simulate("accel13", IndustrialClass(), {0.0, 50.0}, 4);
  ThermalOptions thermal;
  thermal.orders.assign(13, 3);
  const ThermalEstimate est = CalibrateOverTemperature(two.options, two.records, thermal);
  ASSERT_TRUE(est.ok) << est.error;
  for (int k : est.basis.orders) EXPECT_EQ(k, 1);
  ASSERT_FALSE(est.warnings.empty());
  EXPECT_NE(est.order_reasons[0].find("3 asked"), std::string::npos) << est.order_reasons[0];
  EXPECT_TRUE(est.coefficients.allFinite());
}

// Early in a ramp: six poses at six temperatures give 18 equations for mag13's 45 coefficients of
// order 3. The fit neither crashes (a turncald under CI load aborted on it: the null space was
// taken from a thin V) nor claims what it cannot know: the undetermined coefficients have an
// infinite sigma and the rank says so.
// Early in a ramp: 6 poses at 6 temperatures give 18 equations, which cannot carry mag13's 12
// sensor parameters at order 1 (24 coefficients and beta): the orders start lower, every
// coefficient is determined, and the reason says why. 14 poses carry order 1 (37 < 42).
TEST(ThermalCalibrator, FewerEquationsThanCoefficientsCapTheOrders) {
  ThermalRun run = Simulate("mag13", ConsumerClass(), {0.0, 8.0, 16.0, 24.0, 32.0, 40.0}, 6);
  std::vector<PoseRecord> early;
  for (std::size_t k = 0; k < run.records.size(); k += 26) early.push_back(run.records[k + k / 26]);
  ASSERT_EQ(early.size(), 6u);
  ThermalEstimate est = CalibrateOverTemperature(run.options, early, ThermalOptions{});
  ASSERT_TRUE(est.ok) << est.error;
  EXPECT_EQ(est.rank, est.coefficients.size());
  EXPECT_EQ(est.coefficients.size(), 13);
  EXPECT_TRUE(est.sigma.allFinite());
  EXPECT_NE(est.order_reasons[0].find("the highest the 6 poses' 18 equations carry"),
            std::string::npos)
      << est.order_reasons[0];
  ThermalOptions asked;
  asked.orders.assign(13, 2);
  asked.orders[9] = 0;  // beta
  est = CalibrateOverTemperature(run.options, early, asked);
  ASSERT_TRUE(est.ok) << est.error;
  EXPECT_NE(est.order_reasons[0].find("2 asked, but the 6 poses' 18 equations carry at most "
                                      "order 0"),
            std::string::npos)
      << est.order_reasons[0];
  for (std::size_t k = 6; k < 78; k += 13) early.push_back(run.records[k + 26]);
  for (std::size_t k = 10; k < 78; k += 13) early.push_back(run.records[k + 52]);
  ASSERT_GE(early.size(), 14u);
  est = CalibrateOverTemperature(run.options, early, ThermalOptions{});
  ASSERT_TRUE(est.ok) << est.error;
  EXPECT_GE(est.basis.orders[0], 0);
  for (const std::string& r : est.order_reasons) {
    EXPECT_EQ(r.find("equations carry"), std::string::npos) << early.size() << ": " << r;
  }
}

TEST(ThermalCalibrator, RefusesWhatItCannotCalibrateWithTheReason) {
  ThermalRun run = Simulate("accel13", IndustrialClass(), {0.0, 40.0}, 5);
  run.records[3].temp_c.reset();
  ThermalEstimate est = CalibrateOverTemperature(run.options, run.records, ThermalOptions{});
  EXPECT_FALSE(est.ok);
  EXPECT_NE(est.error.find("pose record 4 has no temperature"), std::string::npos) << est.error;

  run.records[3].temp_c = NAN;
  est = CalibrateOverTemperature(run.options, run.records, ThermalOptions{});
  EXPECT_FALSE(est.ok);

  std::string error;
  CalibratorOptions mag22 =
      OptionsForClass(*MakeModel("mag22", ModelContext{}, &error), IndustrialClass());
  est = CalibrateOverTemperature(mag22, {}, ThermalOptions{});
  EXPECT_FALSE(est.ok);
  EXPECT_NE(est.error.find("gauge"), std::string::npos) << est.error;

  ThermalOptions wrong;
  wrong.orders = {1, 2};
  run.records[3].temp_c = 0.0;
  est = CalibrateOverTemperature(run.options, run.records, wrong);
  EXPECT_FALSE(est.ok);
  EXPECT_NE(est.error.find("2 orders given"), std::string::npos) << est.error;
}

}  // namespace
}  // namespace turncal
