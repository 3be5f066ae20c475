// The publish gate over temperature (core/analysis/thermal_gate.h): every gated parameter's sigma
// checked over the whole calibrated range, a failure naming the worst temperature and the part of
// the range that fails; a range too narrow, an undetermined coefficient and a rejected fit refused.

#include "core/analysis/thermal_gate.h"

#include <gtest/gtest.h>

#include <cmath>

namespace turncal {
namespace {

// accel13 over 0 .. 40 degC about t0 = 20: every parameter constant except bx, linear in T, with
// sigma(bx) = sqrt(s0^2 + (s1 (T - 20))^2) (uncorrelated coefficients): smallest at t0, largest at
// the ends.
ThermalEstimate Estimate(const MeasurementModel& model, double s0, double s1) {
  ThermalEstimate e;
  e.ok = true;
  e.model = model.name();
  e.parameters = model.parameters();
  e.basis = ThermalBasis::Constant(model.num_parameters(), 20.0);
  const int bx = model.index_of("bx");
  e.basis.orders[static_cast<std::size_t>(bx)] = 1;
  const int n = e.basis.num_coefficients();
  e.coefficients = Eigen::VectorXd::Zero(n);
  for (int p = 0; p < model.num_parameters(); ++p) {
    e.coefficients[e.basis.index(p, 0)] = model.nominal()[p];
  }
  Eigen::VectorXd var = Eigen::VectorXd::Constant(n, 1e-14);
  var[e.basis.index(bx, 0)] = s0 * s0;
  var[e.basis.index(bx, 1)] = s1 * s1;
  e.covariance = var.asDiagonal();
  e.sigma = var.cwiseSqrt();
  for (int k = 0; k < n; ++k)
    e.coefficient_names.push_back(e.basis.CoefficientName(e.parameters, k));
  e.t_min_c = 0.0;
  e.t_max_c = 40.0;
  e.distinct_temperatures = 5;
  e.rank = n;
  e.dof = 100;
  e.chi2 = 100;
  e.p_value = 0.5;
  return e;
}

TEST(ThermalGate, ChecksSigmaOverTheWholeRangeAndNamesWhereItFails) {
  std::string error;
  const auto model = MakeModel("accel13", ModelContext{}, &error);
  GateOptions gate;
  gate.tolerances.acceleration_mps2 = 1e-3;
  const ThermalGateOptions thermal;
  // 0.5e-3 at t0, sqrt(0.25 + 0.36) e-3 = 0.78e-3 at the ends: passes.
  EXPECT_TRUE(EvaluateThermalGate(*model, Estimate(*model, 0.5e-3, 0.03e-3), gate, thermal).pass);
  // sigma(T) = 1e-3 where |T - 20| = 17.3: fails below 2.7 and above 37.3 degC, worst at 0.
  const GateResult r =
      EvaluateThermalGate(*model, Estimate(*model, 0.5e-3, 0.05e-3), gate, thermal);
  ASSERT_FALSE(r.pass);
  ASSERT_EQ(r.reasons.size(), 1u);
  EXPECT_NE(r.reasons[0].find("bx: sigma"), std::string::npos) << r.reasons[0];
  EXPECT_NE(r.reasons[0].find("at 0.0 degC"), std::string::npos) << r.reasons[0];
  EXPECT_NE(r.reasons[0].find("(from 0.0 to 2.0 and from 38.0 to 40.0 degC)"), std::string::npos)
      << r.reasons[0];
  // The worst sigma per gated parameter, and where (ESTIMATE's precision).
  for (const ThermalPrecision& p :
       WorstPrecisionOverRange(*model, Estimate(*model, 0.5e-3, 0.05e-3), gate, 41)) {
    if (p.name != "bx") continue;
    EXPECT_NEAR(p.sigma, std::hypot(0.5e-3, 20 * 0.05e-3), 1e-12);
    EXPECT_EQ(p.at_c, 0.0);
  }
}

TEST(ThermalGate, RefusesANarrowRangeAnUndeterminedCoefficientAndARejectedFit) {
  std::string error;
  const auto model = MakeModel("accel13", ModelContext{}, &error);
  const GateOptions gate;
  const ThermalGateOptions thermal;
  ThermalEstimate narrow = Estimate(*model, 1e-5, 1e-7);
  narrow.t_max_c = 6.0;
  GateResult r = EvaluateThermalGate(*model, narrow, gate, thermal);
  ASSERT_FALSE(r.pass);
  EXPECT_NE(r.reasons[0].find("span 6.0 degC"), std::string::npos) << r.reasons[0];

  ThermalEstimate undetermined = Estimate(*model, 1e-5, 1e-7);
  const int k = undetermined.basis.index(model->index_of("bx"), 1);
  undetermined.sigma[k] = std::numeric_limits<double>::infinity();
  undetermined.covariance(k, k) = std::numeric_limits<double>::infinity();
  undetermined.rank -= 1;
  r = EvaluateThermalGate(*model, undetermined, gate, thermal);
  ASSERT_FALSE(r.pass);
  EXPECT_NE(r.reasons[0].find("bx*dT"), std::string::npos) << r.reasons[0];

  ThermalEstimate rejected = Estimate(*model, 1e-5, 1e-7);
  rejected.p_value = 1e-9;
  r = EvaluateThermalGate(*model, rejected, gate, thermal);
  ASSERT_FALSE(r.pass);
  EXPECT_NE(r.reasons[0].find("chi^2"), std::string::npos) << r.reasons[0];
}

}  // namespace
}  // namespace turncal
