#include "core/analysis/allan.h"

#include <Eigen/Core>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <limits>

namespace turncal {

double WhiteAvar(double tau_s) { return 1.0 / (2.0 * tau_s); }

double GaussMarkovAvar(double tau_s, double correlation_s) {
  const double u = tau_s / correlation_s;
  if (u < 1e-3) {
    // Series: (2u - 3 + 4e^-u - e^-2u) = 2u^3/3 - u^4/2 + ...: a random walk of q^2 = 2/tau.
    return correlation_s * correlation_s / (tau_s * tau_s) *
           (2 * u * u * u / 3 - u * u * u * u / 2);
  }
  return correlation_s * correlation_s / (tau_s * tau_s) *
         (2 * u - 3 + 4 * std::exp(-u) - std::exp(-2 * u));
}

double RandomWalkAvar(double tau_s) { return tau_s / 3.0; }

std::vector<AllanPoint> OverlappingAllan(const std::vector<double>& x, double dt_s,
                                         int per_decade) {
  std::vector<AllanPoint> out;
  const std::size_t n = x.size();
  if (n < 9 || !(dt_s > 0)) return out;
  // Prefix sums: the mean of x[k .. k+m) is (S[k+m] - S[k]) / m.
  std::vector<double> S(n + 1, 0.0);
  const double x0 = x[0];  // centred: sums of values near gravity lose no digits
  for (std::size_t i = 0; i < n; ++i) S[i + 1] = S[i] + (x[i] - x0);
  std::vector<std::size_t> sizes;
  const double step = std::pow(10.0, 1.0 / std::max(per_decade, 1));
  for (double m = 1; m <= static_cast<double>(n) / 9.0; m *= step) {
    const auto k = static_cast<std::size_t>(std::llround(m));
    if (sizes.empty() || k > sizes.back()) sizes.push_back(k);
  }
  for (std::size_t m : sizes) {
    // sigma^2(m) = 1 / (2 (n - 2m + 1)) sum_k (ybar_{k+m} - ybar_k)^2 over every start k.
    const std::size_t terms = n - 2 * m + 1;
    double sum = 0.0;
    for (std::size_t k = 0; k < terms; ++k) {
      const double a = (S[k + m] - S[k]) / static_cast<double>(m);
      const double b = (S[k + 2 * m] - S[k + m]) / static_cast<double>(m);
      sum += (b - a) * (b - a);
    }
    AllanPoint p;
    p.tau_s = static_cast<double>(m) * dt_s;
    p.adev = std::sqrt(sum / (2.0 * static_cast<double>(terms)));
    p.clusters = static_cast<double>(n) / static_cast<double>(m);
    out.push_back(p);
  }
  return out;
}

double NoiseFit::Adev(double tau_s) const {
  double v = white_density * white_density * WhiteAvar(tau_s) +
             random_walk * random_walk * RandomWalkAvar(tau_s);
  if (gm_sigma > 0 && gm_tau_s > 0) v += gm_sigma * gm_sigma * GaussMarkovAvar(tau_s, gm_tau_s);
  return std::sqrt(v);
}

NoiseFit FitNoiseModel(const std::vector<AllanPoint>& points) {
  NoiseFit best;
  std::vector<AllanPoint> use;
  for (const auto& p : points)
    if (p.adev > 0 && std::isfinite(p.adev) && p.clusters >= 2) use.push_back(p);
  if (use.size() < 3) return best;
  best.longest_tau_s = use.back().tau_s;
  auto floor =
      std::min_element(use.begin(), use.end(),
                       [](const AllanPoint& a, const AllanPoint& b) { return a.adev < b.adev; });
  best.bias_instability = floor->adev / 0.664;
  best.bias_instability_tau_s = floor->tau_s;

  // For each correlation time on a grid: the non-negative least squares of the variances
  // (relative errors: each point's row divided by its measured variance, weighted by
  // sqrt(clusters)), by trying every subset of the three terms and keeping the best feasible.
  const int rows = static_cast<int>(use.size());
  double best_cost = std::numeric_limits<double>::infinity();
  // A correlation time near the shortest cluster time makes the process look white (it would
  // trade against N): the grid starts at 10 of them.
  const double tau_min = 10 * use.front().tau_s, tau_max = use.back().tau_s * 10;
  std::vector<double> grid = {0.0};  // 0: no Gauss-Markov term
  for (double t = tau_min; t <= tau_max; t *= 1.12) grid.push_back(t);
  for (double correlation : grid) {
    Eigen::MatrixXd A(rows, 3);
    Eigen::VectorXd y(rows);
    for (int i = 0; i < rows; ++i) {
      const auto& p = use[static_cast<std::size_t>(i)];
      const double w = std::sqrt(p.clusters) / (p.adev * p.adev);
      A(i, 0) = w * WhiteAvar(p.tau_s);
      A(i, 1) = correlation > 0 ? w * GaussMarkovAvar(p.tau_s, correlation) : 0.0;
      A(i, 2) = w * RandomWalkAvar(p.tau_s);
      y[i] = w * p.adev * p.adev;
    }
    for (int mask = 1; mask < 8; ++mask) {
      if ((mask & 2) && correlation <= 0) continue;
      std::vector<int> cols;
      for (int c = 0; c < 3; ++c)
        if (mask & (1 << c)) cols.push_back(c);
      Eigen::MatrixXd Ac(rows, static_cast<int>(cols.size()));
      for (std::size_t c = 0; c < cols.size(); ++c) Ac.col(static_cast<int>(c)) = A.col(cols[c]);
      const Eigen::VectorXd coef = Ac.colPivHouseholderQr().solve(y);
      if (!coef.allFinite() || coef.minCoeff() < 0) continue;
      const double cost = (Ac * coef - y).squaredNorm();
      if (cost < best_cost) {
        best_cost = cost;
        NoiseFit f = best;
        f.ok = true;
        f.white_density = f.gm_sigma = f.gm_tau_s = f.random_walk = 0.0;
        for (std::size_t c = 0; c < cols.size(); ++c) {
          const double v = std::sqrt(coef[static_cast<int>(c)]);
          if (cols[c] == 0) f.white_density = v;
          if (cols[c] == 1) {
            f.gm_sigma = v;
            f.gm_tau_s = correlation;
          }
          if (cols[c] == 2) f.random_walk = v;
        }
        best = f;
      }
    }
  }
  if (best.ok) {
    double e = 0;
    for (const auto& p : use) e += std::pow(std::log(best.Adev(p.tau_s) / p.adev), 2);
    best.rms_log_error = std::sqrt(e / static_cast<double>(use.size()));
  }
  return best;
}

}  // namespace turncal
