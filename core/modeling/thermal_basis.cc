#include "core/modeling/thermal_basis.h"

#include <cassert>
#include <cmath>

namespace turncal {

ThermalBasis ThermalBasis::Constant(int num_parameters, double t0_c) {
  ThermalBasis b;
  b.t0_c = t0_c;
  b.orders.assign(static_cast<std::size_t>(num_parameters), 0);
  return b;
}

int ThermalBasis::num_coefficients() const {
  int n = 0;
  for (int k : orders) n += k + 1;
  return n;
}

int ThermalBasis::index(int p, int j) const {
  assert(p >= 0 && p < num_parameters() && j >= 0 && j <= orders[static_cast<std::size_t>(p)]);
  int n = 0;
  for (int q = 0; q < p; ++q) n += orders[static_cast<std::size_t>(q)] + 1;
  return n + j;
}

Eigen::MatrixXd ThermalBasis::Design(double temp_c) const {
  const double u = (temp_c - t0_c) / scale_c;
  Eigen::MatrixXd d = Eigen::MatrixXd::Zero(num_parameters(), num_coefficients());
  int col = 0;
  for (int p = 0; p < num_parameters(); ++p) {
    double power = 1.0;
    for (int j = 0; j <= orders[static_cast<std::size_t>(p)]; ++j, ++col) {
      d(p, col) = power;
      power *= u;
    }
  }
  return d;
}

Eigen::VectorXd ThermalBasis::Theta(const Eigen::VectorXd& coefficients, double temp_c) const {
  return Design(temp_c) * coefficients;
}

ThermalBasis ThermalBasis::Unscaled() const {
  ThermalBasis b = *this;
  b.scale_c = 1.0;
  return b;
}

Eigen::VectorXd ThermalBasis::ToUnscaled() const {
  Eigen::VectorXd m(num_coefficients());
  int col = 0;
  for (int p = 0; p < num_parameters(); ++p) {
    for (int j = 0; j <= orders[static_cast<std::size_t>(p)]; ++j) m[col++] = std::pow(scale_c, -j);
  }
  return m;
}

Eigen::VectorXd ThermalBasis::Raised(const Eigen::VectorXd& coefficients,
                                     const ThermalBasis& to) const {
  Eigen::VectorXd out = Eigen::VectorXd::Zero(to.num_coefficients());
  for (int p = 0; p < num_parameters(); ++p) {
    for (int j = 0; j <= orders[static_cast<std::size_t>(p)]; ++j) {
      out[to.index(p, j)] = coefficients[index(p, j)];
    }
  }
  return out;
}

std::string ThermalBasis::CoefficientName(const std::vector<ParameterInfo>& parameters,
                                          int index) const {
  int col = 0;
  for (int p = 0; p < num_parameters(); ++p) {
    const int k = orders[static_cast<std::size_t>(p)];
    if (index <= col + k) {
      const int j = index - col;
      const std::string& name = parameters[static_cast<std::size_t>(p)].name;
      if (j == 0) return name;
      return name + "*dT" + (j == 1 ? std::string() : "^" + std::to_string(j));
    }
    col += k + 1;
  }
  return "?";
}

}  // namespace turncal
