#include "core/analysis/rate_linearity.h"

#include <fmt/format.h>

#include <Eigen/LU>
#include <boost/math/special_functions/gamma.hpp>
#include <cmath>
#include <map>

#include "core/frames/units.h"

namespace turncal {

namespace {

struct Segment {
  double rate_dps = 0.0;  // signed
  double e = 0.0, sigma = 0.0;
};

// Weighted mean and its sigma.
std::pair<double, double> WeightedMean(const std::vector<Segment>& s) {
  double w = 0.0, we = 0.0;
  for (const auto& x : s) {
    w += 1.0 / (x.sigma * x.sigma);
    we += x.e / (x.sigma * x.sigma);
  }
  return {we / w, 1.0 / std::sqrt(w)};
}

}  // namespace

RateLinearity AnalyzeRateLinearity(const MeasurementModel& model, const Eigen::VectorXd& theta,
                                   const std::vector<WeightedPose>& records) {
  RateLinearity out;
  if (model.sensor() != SensorKind::kGyroscope) return out;
  std::vector<Segment> segments;
  for (const WeightedPose& w : records) {
    if (w.raw_residual || !w.pose.is_rate()) continue;
    TablePose reversed = w.pose;
    reversed.rate_radps = -reversed.rate_radps;
    // The table's part: the Earth's rate, the bias and the g-sensitivity cancel.
    const Eigen::Vector3d predicted = model.Predict(theta, w.pose);
    const Eigen::Vector3d p = 0.5 * (predicted - model.Predict(theta, reversed));
    const double norm = p.norm();
    if (!(norm > 0)) continue;
    const Eigen::Vector3d u = p / norm;
    const Eigen::Matrix3d cov = (w.sqrt_information.transpose() * w.sqrt_information).inverse();
    Segment s;
    s.rate_dps = w.pose.rate_radps * kDegPerRad;
    s.e = (w.measured - predicted).dot(u) / norm;
    s.sigma = std::sqrt(std::max(u.dot(cov * u), 0.0)) / norm;
    if (!std::isfinite(s.e) || !(s.sigma > 0)) continue;
    segments.push_back(s);
  }
  out.segments = static_cast<int>(segments.size());
  if (segments.empty()) {
    out.finding = "no rate segment";
    return out;
  }
  std::map<long, std::vector<Segment>> by_level;
  std::vector<Segment> positive, negative;
  for (const auto& s : segments) {
    by_level[std::lround(std::abs(s.rate_dps) * 10.0)].push_back(s);
    (s.rate_dps > 0 ? positive : negative).push_back(s);
  }
  for (const auto& [key, level] : by_level) {
    const auto [mean, sigma] = WeightedMean(level);
    out.levels.push_back(
        {static_cast<double>(key) / 10.0, static_cast<int>(level.size()), mean, sigma});
  }
  if (!positive.empty() && !negative.empty()) {
    const auto [mp, sp] = WeightedMean(positive);
    const auto [mn, sn] = WeightedMean(negative);
    out.has_asymmetry = true;
    out.asymmetry = mp - mn;
    out.asymmetry_sigma = std::hypot(sp, sn);
  }
  if (out.levels.size() < 2) {
    out.finding = fmt::format(
        "{} rate segment(s) at one rate ({:g} deg/s): a second rate would show whether the scale "
        "depends on the rate",
        out.segments, out.levels.front().rate_dps);
    return out;
  }
  out.compared = true;
  // chi^2 of the level means about their weighted mean.
  std::vector<Segment> means;
  for (const auto& l : out.levels) means.push_back({l.rate_dps, l.scale_error, l.sigma});
  const double common = WeightedMean(means).first;
  for (const auto& m : means) out.chi2 += std::pow((m.e - common) / m.sigma, 2);
  out.dof = static_cast<int>(means.size()) - 1;
  out.p_value = boost::math::gamma_q(out.dof / 2.0, out.chi2 / 2.0);
  // Weighted least squares e = a + slope |rate| over the segments.
  Eigen::Matrix2d N = Eigen::Matrix2d::Zero();
  Eigen::Vector2d b = Eigen::Vector2d::Zero();
  for (const auto& s : segments) {
    const Eigen::Vector2d x(1.0, std::abs(s.rate_dps));
    const double w = 1.0 / (s.sigma * s.sigma);
    N += w * x * x.transpose();
    b += w * s.e * x;
  }
  const Eigen::Matrix2d cov = N.inverse();
  const Eigen::Vector2d ab = cov * b;
  out.slope_per_dps = ab[1];
  out.slope_sigma = std::sqrt(cov(1, 1));
  const double span = out.levels.back().rate_dps - out.levels.front().rate_dps;
  out.finding = fmt::format(
      "from {:g} to {:g} deg/s the scale changes by {:+.1f} +- {:.1f} ppm ({:.1f} sigma; chi^2 "
      "{:.1f} on {} dof, p = {:.3g}): {}",
      out.levels.front().rate_dps, out.levels.back().rate_dps, out.slope_per_dps * span * 1e6,
      out.slope_sigma * span * 1e6, std::abs(out.slope_per_dps) / out.slope_sigma, out.chi2,
      out.dof, out.p_value,
      out.p_value < 0.001 ? "the scale depends on the rate (non-linear), beyond the noise"
                          : "linear within the noise");
  return out;
}

}  // namespace turncal
