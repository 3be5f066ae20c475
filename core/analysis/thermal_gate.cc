#include "core/analysis/thermal_gate.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace turncal {

bool ThermalGateOptions::IsValid(std::string* error) const {
  if (!(min_span_c >= 0 && std::isfinite(min_span_c))) {
    if (error) *error = "[thermal] min_span_c must be >= 0 degC";
    return false;
  }
  if (grid_points < 2 || grid_points > 10001) {
    if (error) *error = "[thermal] grid_points must be in [2, 10001]";
    return false;
  }
  return true;
}

namespace {

std::vector<double> Grid(const ThermalEstimate& e, int points) {
  std::vector<double> t;
  const double span = e.t_max_c - e.t_min_c;
  for (int i = 0; i < points; ++i) t.push_back(e.t_min_c + span * i / (points - 1));
  return t;
}

// A NaN sigma (an undetermined coefficient) is the worst there is.
double Worst(double sigma) {
  return std::isnan(sigma) ? std::numeric_limits<double>::infinity() : sigma;
}

}  // namespace

std::vector<ThermalPrecision> WorstPrecisionOverRange(const MeasurementModel& model,
                                                      const ThermalEstimate& e,
                                                      const GateOptions& options, int grid_points) {
  std::vector<ThermalPrecision> out;
  if (!e.ok) return out;
  const std::vector<double> grid = Grid(e, grid_points);
  std::vector<Eigen::VectorXd> sigma;
  for (double t : grid) sigma.push_back(e.SigmaAt(t));
  for (int j : GatedParameters(model)) {
    const ParameterInfo& p = model.parameters()[static_cast<std::size_t>(j)];
    ThermalPrecision w{p.name, -1.0, grid.front(), ToleranceFor(p, options)};
    for (std::size_t g = 0; g < grid.size(); ++g) {
      const double s = Worst(sigma[g][j]);
      if (s > w.sigma) w.sigma = s, w.at_c = grid[g];
    }
    out.push_back(w);
  }
  return out;
}

GateResult EvaluateThermalGate(const MeasurementModel& model, const ThermalEstimate& e,
                               const GateOptions& options, const ThermalGateOptions& thermal) {
  GateResult result;
  auto& reasons = result.reasons;
  if (!e.ok) {
    reasons.push_back("no estimate: " + e.error);
    return result;
  }
  // 1. A range.
  const double span = e.t_max_c - e.t_min_c;
  if (!(span >= thermal.min_span_c)) {
    reasons.push_back(fmt::format(
        "the poses span {:.1f} degC ({:.1f} to {:.1f}): a calibration over temperature needs at "
        "least {:.1f} degC (take poses at other temperatures)",
        span, e.t_min_c, e.t_max_c, thermal.min_span_c));
  }
  // 2. Every coefficient determined.
  const auto n = static_cast<int>(e.coefficients.size());
  if (e.rank < n) {
    std::string names;
    for (Eigen::Index k = 0; k < e.sigma.size(); ++k) {
      if (!std::isfinite(e.sigma[k])) {
        names += (names.empty() ? "" : " ") + e.coefficient_names[static_cast<std::size_t>(k)];
      }
    }
    reasons.push_back(fmt::format(
        "rank {} of {}: the poses leave coefficients undetermined{}{} (take the poses at more "
        "temperatures)",
        e.rank, n, names.empty() ? "" : ": ", names));
  }
  // 3. Precision over the whole range, naming where it fails.
  const std::vector<double> grid = Grid(e, thermal.grid_points);
  std::vector<Eigen::VectorXd> sigma;
  for (double t : grid) sigma.push_back(e.SigmaAt(t));
  for (int j : GatedParameters(model)) {
    const ParameterInfo& p = model.parameters()[static_cast<std::size_t>(j)];
    const double tolerance = ToleranceFor(p, options);
    double worst = -1.0, worst_at = grid.front();
    // The parts of the range that fail, as runs of grid points.
    std::vector<std::pair<double, double>> failing;
    bool in_run = false;
    for (std::size_t g = 0; g < grid.size(); ++g) {
      const double s = Worst(sigma[g][j]);
      if (!(s > tolerance)) {
        in_run = false;
        continue;
      }
      if (in_run) {
        failing.back().second = grid[g];
      } else {
        failing.emplace_back(grid[g], grid[g]);
      }
      in_run = true;
      if (s > worst) worst = s, worst_at = grid[g];
    }
    if (failing.empty()) continue;
    std::string where;
    if (failing.size() == 1 && failing[0].first == grid.front() &&
        failing[0].second == grid.back()) {
      where = "over the whole range";
    } else {
      for (const auto& [from, to] : failing) {
        where += where.empty() ? "" : " and ";
        where += from == to ? fmt::format("at {:.1f}", from)
                            : fmt::format("from {:.1f} to {:.1f}", from, to);
      }
      where += " degC";
    }
    reasons.push_back(fmt::format("{}: sigma {} at {:.1f} degC exceeds the tolerance {} ({})",
                                  p.name, FormatSigma(p, worst), worst_at,
                                  FormatSigma(p, tolerance), where));
  }
  // 4. chi^2 consistent with the noise; 5. no extreme pose.
  AddFitReasons(e.chi2, e.dof, e.p_value, e.fit, e.residuals, model.sensor(), options,
                "bias drift between poses, a temperature dependence of higher order than the data "
                "carry, or the wrong model",
                &result);
  result.notes.push_back(fmt::format("calibrated range {:.1f} to {:.1f} degC ({} temperatures)",
                                     e.t_min_c, e.t_max_c, e.distinct_temperatures));
  result.pass = reasons.empty();
  return result;
}

}  // namespace turncal
