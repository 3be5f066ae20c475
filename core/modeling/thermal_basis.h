#pragma once
// Parameters as functions of the sensor's die temperature (MODELS.md "Temperature: parameters as
// functions"; issue 36): each parameter p of a model is a polynomial in (T - t0),
//   theta_p(T) = c_p0 + c_p1 u + ... + c_pk u^k,   u = (T - t0) / scale_c,
// of its own order k (0: the parameter does not depend on temperature). The coefficients are
// grouped by parameter: [c_00 .. c_0k0, c_10 .. c_1k1, ...]. With scale_c = 1 (a result's basis)
// c_pj is in the parameter's unit per degree C^j; an estimator may scale u to [-1, 1] over the
// temperatures it saw, which keeps the columns of its Jacobian of one size.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/modeling/parameter.h"

namespace turncal {

struct ThermalBasis {
  double t0_c = 25.0;
  double scale_c = 1.0;
  std::vector<int> orders;  // per model parameter, >= 0

  // A basis of `num_parameters` parameters, every order 0.
  static ThermalBasis Constant(int num_parameters, double t0_c);

  int num_parameters() const { return static_cast<int>(orders.size()); }
  int num_coefficients() const;
  // Index of parameter p's coefficient of power j (j <= orders[p]).
  int index(int p, int j) const;
  // The P x N matrix D(T) with theta(T) = D(T) c.
  Eigen::MatrixXd Design(double temp_c) const;
  Eigen::VectorXd Theta(const Eigen::VectorXd& coefficients, double temp_c) const;
  // The same basis with scale_c = 1, and the map from this basis's coefficients to that one's
  // (diagonal: 1 / scale_c^j).
  ThermalBasis Unscaled() const;
  Eigen::VectorXd ToUnscaled() const;
  // Coefficients of this basis with the same parameters at another set of orders (at least as
  // high for each parameter): the extra coefficients zero.
  Eigen::VectorXd Raised(const Eigen::VectorXd& coefficients, const ThermalBasis& to) const;
  // "bx", "bx*dT", "bx*dT^2": a coefficient's name, the parameter's coefficient of dT^j with
  // dT = T - t0 (in the unscaled basis: the parameter's unit per degree C^j).
  std::string CoefficientName(const std::vector<ParameterInfo>& parameters, int index) const;
};

}  // namespace turncal
