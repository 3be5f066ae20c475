#pragma once
// Calibration over temperature (issue 36; MODELS.md "Temperature: parameters as functions"): every
// parameter of a measurement model a polynomial in the sensor's die temperature, estimated jointly
// from pose records taken at several temperatures, each parameter's order chosen from the data.
//
// The records are weighed exactly as the isothermal Calibrator weighs them (the same options: the
// white floor, the pose-to-pose offset, a rate segment's rate accuracy), and with a bias drift
// model (CalibratorOptions::drift) by generalised least squares over all poses in time order
// (core/estimation/gls_whitening.h): the biases' coefficients are then the bias over the latest
// pose's window, as a function of temperature. The start is the isothermal calibration of all the
// records (every parameter at order 0). Unless the orders are given, every sensor parameter then
// gets the highest order the temperatures carry (max_order, and no more coefficients than there
// are distinct temperatures); the mounting and installation parameters, which do not depend on the
// sensor's temperature, order 0. Then, one at a time, the top coefficient closest to zero is
// dropped while it is within drop_below_sigmas of zero: a parameter that does not depend on
// temperature ends at order 0 and costs nothing, and a dependence the data can see is kept.
// (Raising orders from 0 while an information criterion falls was tried first and measured
// dishonest: it drops dependences of about one sigma, which then bias the other parameters between
// the soaks; std z up to 2.1 at held-out temperatures, docs/THERMAL.md.) The covariance is the
// inverse Fisher information of the chosen polynomials (conditional on the orders), inflated by
// chi^2/dof when the fit is rejected, as the Calibrator does; sigma at any temperature follows from
// it (SigmaAt).
//
// Models with a gauge (mag22) are refused: the gauge of a temperature-dependent K is not yet
// defined. So are records without a temperature, and a gyroscope's moves are not used (the pose
// records and rate segments are).

#include <Eigen/Core>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "core/estimation/calibrator.h"
#include "core/estimation/fit_check.h"
#include "core/estimation/pose_record.h"
#include "core/modeling/thermal_basis.h"

namespace turncal {

struct ThermalOptions {
  // The highest order any parameter may get (and no more than distinct temperatures - 1).
  int max_order = 3;
  // Record temperatures closer than this count as one when the distinct temperatures are counted.
  double distinct_resolution_c = 1.0;
  // The reference temperature t0 of the result's coefficients; NaN: the middle of the records'
  // range.
  double t0_c = std::numeric_limits<double>::quiet_NaN();
  // Each parameter's order, in the model's parameter order (empty: chosen from the data). An
  // order the temperatures cannot carry is lowered to the highest they can, with a warning.
  std::vector<int> orders;
  // Orders chosen from the data: a parameter's top coefficient is dropped (and the fit repeated)
  // while it is within this many sigma of zero, the closest first.
  double drop_below_sigmas = 0.25;

  bool IsValid(std::string* error) const;
};

struct ThermalEstimate {
  bool ok = false;
  std::string error;  // why not, when !ok
  std::string model;
  std::vector<ParameterInfo> parameters;
  // The polynomials: coefficients in each parameter's unit per degree C^j about basis.t0_c
  // (basis.scale_c is 1), their covariance and sigma (inf for an undetermined coefficient).
  ThermalBasis basis;
  Eigen::VectorXd coefficients;
  Eigen::MatrixXd covariance;
  Eigen::VectorXd sigma;
  std::vector<std::string> coefficient_names;  // "bx", "bx*dT", "bx*dT^2", ...
  // Per parameter: why it has its order ("order 1: the coefficient(s) above it were 0.31, 0.72
  // sigma from zero (dropped below 1)", "order 0: 1 distinct temperature(s) carry no higher
  // order", "order 1: as asked").
  std::vector<std::string> order_reasons;
  // The calibrated range: the records' lowest and highest temperature.
  double t_min_c = std::numeric_limits<double>::quiet_NaN();
  double t_max_c = std::numeric_limits<double>::quiet_NaN();
  int distinct_temperatures = 0;
  int poses = 0;
  int rank = 0;                         // of the whitened Jacobian, out of coefficients.size()
  std::vector<PoseResidual> residuals;  // per record, in the records' order (drift: innovations)
  double chi2 = 0.0;
  int dof = 0;
  double p_value = 1.0;
  double covariance_scale = 1.0;  // > 1 when inflated by chi^2/dof
  FitCheck fit;
  int solves = 0;  // of the order selection, the final one included
  std::vector<std::string> warnings;

  // Each parameter at a temperature, its covariance and sigma (in the model's parameter order).
  Eigen::VectorXd ThetaAt(double temp_c) const;
  Eigen::MatrixXd CovarianceAt(double temp_c) const;
  Eigen::VectorXd SigmaAt(double temp_c) const;
  // A parameter's order by name (-1 when unknown).
  int order_of(std::string_view name) const;
  // Range, orders and each parameter at t0 and at the range's ends with its sigma.
  std::string BriefReport() const;
};

// Calibrates `options.model` over temperature from `records` (each with temp_c). !ok with a reason
// when the options are invalid, the model has a gauge, a record cannot be added or has no
// temperature, or there are fewer poses than the model needs.
ThermalEstimate CalibrateOverTemperature(const CalibratorOptions& options,
                                         const std::vector<PoseRecord>& records,
                                         const ThermalOptions& thermal);

}  // namespace turncal
