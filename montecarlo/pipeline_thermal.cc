#include "montecarlo/pipeline_thermal.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/estimation/thermal_calibrator.h"
#include "protocol/thermal_json.h"

namespace turncal::montecarlo {

std::vector<double> DefaultHeldOutTemperatures(const ChamberProfile& chamber) {
  std::vector<double> setpoints = {chamber.start_c};
  for (const ChamberStep& s : chamber.steps) setpoints.push_back(s.setpoint_c);
  std::sort(setpoints.begin(), setpoints.end());
  setpoints.erase(std::unique(setpoints.begin(), setpoints.end(),
                              [](double a, double b) { return std::abs(a - b) < 1e-9; }),
                  setpoints.end());
  std::vector<double> out;
  if (setpoints.size() >= 3) {
    for (std::size_t i = 0; i + 1 < setpoints.size(); ++i) {
      out.push_back(0.5 * (setpoints[i] + setpoints[i + 1]));
    }
    return out;
  }
  const double lo = setpoints.front(), hi = setpoints.back();
  for (double f : {0.25, 0.5, 0.75}) out.push_back(lo + f * (hi - lo));
  return out;
}

std::vector<std::string> ThermalScoredNames(const MeasurementModel& model,
                                            const ThermalBasis* coefficients,
                                            const std::vector<double>& held_out_c) {
  std::vector<std::string> names;
  if (coefficients) {
    for (int k = 0; k < coefficients->num_coefficients(); ++k) {
      names.push_back(coefficients->CoefficientName(model.parameters(), k));
    }
  }
  for (double t : held_out_c) {
    for (const ParameterInfo& p : model.parameters()) {
      names.push_back(fmt::format("{}@{:g}C", p.name, t));
    }
  }
  return names;
}

bool ScoreThermalRun(const MeasurementModel& model, const nlohmann::json& m,
                     const ThermalTruth& truth, const Eigen::Vector3d& bias_offset,
                     bool coefficients, const std::vector<double>& held_out_c, Eigen::VectorXd* z,
                     std::string* error) {
  ThermalEstimate e;
  if (!protocol::ReadThermalEstimate(model, m, &e, error)) return false;
  const int bias = model.index_of("bx");
  std::vector<double> out;
  if (coefficients) {
    if (e.basis.orders != truth.basis.orders || std::abs(e.basis.t0_c - truth.basis.t0_c) > 1e-9) {
      *error = "the fit's orders or t0 are not the truth's";
      return false;
    }
    Eigen::VectorXd c = truth.coefficients;
    for (int axis = 0; axis < 3; ++axis) c[truth.basis.index(bias + axis, 0)] += bias_offset[axis];
    for (Eigen::Index k = 0; k < c.size(); ++k)
      out.push_back((e.coefficients[k] - c[k]) / e.sigma[k]);
  }
  for (double t : held_out_c) {
    Eigen::VectorXd want = truth.ThetaAt(t);
    want.segment<3>(bias) += bias_offset;
    const Eigen::VectorXd got = e.ThetaAt(t), sigma = e.SigmaAt(t);
    for (Eigen::Index p = 0; p < got.size(); ++p) out.push_back((got[p] - want[p]) / sigma[p]);
  }
  *z = Eigen::Map<const Eigen::VectorXd>(out.data(), static_cast<Eigen::Index>(out.size()));
  return true;
}

}  // namespace turncal::montecarlo
