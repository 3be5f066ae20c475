// ThermalEstimate's accessors and report (core/estimation/thermal_calibrator.h).

#include <fmt/format.h>

#include <cmath>

#include "core/estimation/thermal_calibrator.h"

namespace turncal {

Eigen::VectorXd ThermalEstimate::ThetaAt(double temp_c) const {
  return basis.Theta(coefficients, temp_c);
}

Eigen::MatrixXd ThermalEstimate::CovarianceAt(double temp_c) const {
  const Eigen::MatrixXd d = basis.Design(temp_c);
  return d * covariance * d.transpose();
}

Eigen::VectorXd ThermalEstimate::SigmaAt(double temp_c) const {
  // A parameter with an undetermined coefficient has no finite sigma at any temperature.
  Eigen::VectorXd s = CovarianceAt(temp_c).diagonal().cwiseMax(0.0).cwiseSqrt();
  for (int p = 0; p < basis.num_parameters(); ++p) {
    for (int j = 0; j <= basis.orders[static_cast<std::size_t>(p)]; ++j) {
      if (!std::isfinite(sigma[basis.index(p, j)])) s[p] = INFINITY;
    }
  }
  return s;
}

int ThermalEstimate::order_of(std::string_view name) const {
  for (std::size_t p = 0; p < parameters.size() && p < basis.orders.size(); ++p) {
    if (parameters[p].name == name) return basis.orders[p];
  }
  return -1;
}

std::string ThermalEstimate::BriefReport() const {
  if (!ok) return fmt::format("{} over temperature: failed: {}", model, error);
  std::string out = fmt::format(
      "{} over temperature: {} poses at {} distinct temperatures, {:.1f} .. {:.1f} degC "
      "(t0 {:.1f}); {} coefficients, chi2/dof = {:.1f}/{} (p = {:.3g}), {} solves\n",
      model, poses, distinct_temperatures, t_min_c, t_max_c, basis.t0_c, coefficients.size(), chi2,
      dof, p_value, solves);
  const double temps[3] = {t_min_c, basis.t0_c, t_max_c};
  Eigen::VectorXd theta[3], sig[3];
  for (int k = 0; k < 3; ++k) theta[k] = ThetaAt(temps[k]), sig[k] = SigmaAt(temps[k]);
  out +=
      fmt::format("  {:<8} {:>5}  {:>28} {:>28} {:>28}\n", "param", "order",
                  fmt::format("at {:.1f} degC", temps[0]), fmt::format("at {:.1f} degC", temps[1]),
                  fmt::format("at {:.1f} degC", temps[2]));
  for (std::size_t p = 0; p < parameters.size(); ++p) {
    out += fmt::format("  {:<8} {:>5}", parameters[p].name, basis.orders[p]);
    for (int k = 0; k < 3; ++k) {
      const auto v = ForDisplay(parameters[p], theta[k][static_cast<Eigen::Index>(p)], false);
      out += fmt::format("  {:>12.5g} +- {:<9} {:<3}", v.value,
                         FormatSigma(parameters[p], sig[k][static_cast<Eigen::Index>(p)]), "");
    }
    out += "\n";
  }
  for (std::size_t p = 0; p < parameters.size() && p < order_reasons.size(); ++p) {
    if (basis.orders[p] > 0) out += fmt::format("  {}: {}\n", parameters[p].name, order_reasons[p]);
  }
  for (const auto& w : warnings) out += "  warning: " + w + "\n";
  return out;
}

}  // namespace turncal
