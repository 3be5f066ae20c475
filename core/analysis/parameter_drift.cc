#include "core/analysis/parameter_drift.h"

#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>
#include <map>

namespace turncal {

namespace {

struct Line {
  double intercept = 0.0, slope = 0.0;  // at t = reference
  double var_intercept = 0.0, var_slope = 0.0;
  double chi2 = 0.0;
};

// The weighted line through (t - reference, value) with variances sigma^2 + tau2.
Line FitLine(const std::vector<DriftPoint>& p, double reference, double tau2) {
  double sw = 0, st = 0, stt = 0, sy = 0, sty = 0;
  for (const DriftPoint& d : p) {
    const double w = 1.0 / (d.sigma * d.sigma + tau2), t = d.t_s - reference;
    sw += w, st += w * t, stt += w * t * t, sy += w * d.value, sty += w * t * d.value;
  }
  Line l;
  const double det = sw * stt - st * st;
  if (!(det > 0)) return l;
  l.slope = (sw * sty - st * sy) / det;
  l.intercept = (stt * sy - st * sty) / det;
  l.var_slope = sw / det;
  l.var_intercept = stt / det;
  for (const DriftPoint& d : p) {
    const double r = d.value - l.intercept - l.slope * (d.t_s - reference);
    l.chi2 += r * r / (d.sigma * d.sigma + tau2);
  }
  return l;
}

}  // namespace

ParameterDrift AnalyseParameterDrift(std::vector<DriftPoint> points, double tolerance) {
  ParameterDrift r;
  r.tolerance = tolerance;
  points.erase(std::remove_if(points.begin(), points.end(),
                              [](const DriftPoint& d) {
                                return !std::isfinite(d.t_s) || !std::isfinite(d.value) ||
                                       !(d.sigma >= 0) || !std::isfinite(d.sigma);
                              }),
               points.end());
  std::sort(points.begin(), points.end(),
            [](const DriftPoint& a, const DriftPoint& b) { return a.t_s < b.t_s; });
  r.calibrations = static_cast<int>(points.size());
  if (points.size() < 3) {
    r.error = "fewer than three calibrations with a value";
    return r;
  }
  r.first_t_s = points.front().t_s;
  r.last_t_s = points.back().t_s;

  // Repeatability: the pooled scatter within UTC days.
  std::map<long long, std::vector<const DriftPoint*>> days;
  for (const DriftPoint& d : points)
    days[static_cast<long long>(std::floor(d.t_s / 86400.0))].push_back(&d);
  double ss = 0, sigma2 = 0;
  int dof = 0, in_groups = 0;
  for (const auto& [day, group] : days) {
    if (group.size() < 2) continue;
    ++r.repeat_groups;
    double mean = 0;
    for (const DriftPoint* d : group) mean += d->value;
    mean /= static_cast<double>(group.size());
    for (const DriftPoint* d : group) {
      ss += (d->value - mean) * (d->value - mean);
      sigma2 += d->sigma * d->sigma;
      ++in_groups;
    }
    dof += static_cast<int>(group.size()) - 1;
  }
  if (dof > 0) {
    r.repeat_dof = dof;
    const double var = ss / dof;
    r.repeatability = std::sqrt(var);
    const boost::math::chi_squared chi2(dof);
    r.repeatability_low95 =
        std::sqrt(var * dof / boost::math::quantile(boost::math::complement(chi2, 0.025)));
    r.repeatability_high95 = std::sqrt(var * dof / boost::math::quantile(chi2, 0.025));
    r.repeatability_beyond = std::sqrt(std::max(0.0, var - sigma2 / in_groups));
  }

  // The trend, with the wander tau^2 at which chi^2 = dof (Paule-Mandel, by bisection on a
  // monotone function of tau^2).
  r.dof = r.calibrations - 2;
  // A calibration without a sigma gets the smallest one's, or, with none, the scatter alone.
  double smallest = INFINITY;
  for (const DriftPoint& d : points)
    if (d.sigma > 0) smallest = std::min(smallest, d.sigma);
  double spread = 0, mean = 0;
  for (const DriftPoint& d : points) mean += d.value / static_cast<double>(points.size());
  for (const DriftPoint& d : points) spread += (d.value - mean) * (d.value - mean);
  const double floor_sigma =
      std::isfinite(smallest) ? smallest : std::sqrt(spread / points.size()) + 1e-300;
  for (DriftPoint& d : points)
    if (!(d.sigma > 0)) d.sigma = floor_sigma;
  double tau2 = 0.0;
  if (FitLine(points, r.last_t_s, 0.0).chi2 > r.dof) {
    double lo = 0.0, hi = spread + 1e-300;
    while (FitLine(points, r.last_t_s, hi).chi2 > r.dof) hi *= 4;
    for (int i = 0; i < 100; ++i) {
      const double mid = 0.5 * (lo + hi);
      (FitLine(points, r.last_t_s, mid).chi2 > r.dof ? lo : hi) = mid;
    }
    tau2 = hi;
  }
  const Line line = FitLine(points, r.last_t_s, tau2);
  r.wander = std::sqrt(tau2);
  r.chi2 = FitLine(points, r.last_t_s, 0.0).chi2;
  r.value_at_last = line.intercept;
  r.value_at_last_sigma = std::sqrt(line.var_intercept);
  r.slope_per_s = line.slope;
  r.slope_sigma_per_s = std::sqrt(line.var_slope);
  r.trend_resolved = std::fabs(line.slope) > 2.0 * r.slope_sigma_per_s;
  if (tolerance > 0 && std::isfinite(tolerance)) {
    const double b = std::fabs(line.slope), s = r.slope_sigma_per_s;
    r.not_before_t_s = r.last_t_s + tolerance / (b + 1.96 * s);
    if (r.trend_resolved) {
      r.has_recalibration = true;
      r.recalibrate_t_s = r.last_t_s + tolerance / b;
      r.recalibrate_sigma_s = tolerance * s / (b * b);
    }
  }
  r.ok = true;
  return r;
}

}  // namespace turncal
