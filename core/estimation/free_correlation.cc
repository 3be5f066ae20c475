#include "core/estimation/free_correlation.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "core/estimation/free_motion.h"

namespace turncal {
namespace {
constexpr double kOutlierSigmas = 4.0;
}  // namespace

double MotionCorrelation::at_spacing() const {
  return correlated() ? std::exp(-spacing_s / tau_s) : 0.0;
}

MotionCorrelation MeasureMotionCorrelation(std::vector<MotionResidual> residuals,
                                           double min_lag_one, double sigmas,
                                           int fitted_parameters) {
  MotionCorrelation out;
  std::sort(residuals.begin(), residuals.end(),
            [](const MotionResidual& a, const MotionResidual& b) { return a.t_s < b.t_s; });
  std::vector<double> steps;
  for (std::size_t k = 1; k < residuals.size(); ++k) {
    const double dt = residuals[k].t_s - residuals[k - 1].t_s;
    if (dt > 0) steps.push_back(dt);
  }
  if (steps.size() < 20) return out;
  out.spacing_s = MedianOf(std::move(steps));
  const double max_gap = 3.0 * out.spacing_s;
  // A disturbance (a magnet passing) is smooth and would read as correlation: the values beyond
  // kOutlierSigmas robust sigmas (1.4826 x the median |r|) are left out of the pairs.
  std::vector<double> magnitudes;
  for (const MotionResidual& m : residuals) magnitudes.push_back(std::abs(m.r));
  const double bound = kOutlierSigmas * 1.4826 * MedianOf(std::move(magnitudes));
  double rr = 0, aa = 0, bb = 0;
  std::vector<double> dts;
  for (std::size_t k = 1; k < residuals.size(); ++k) {
    const double dt = residuals[k].t_s - residuals[k - 1].t_s;
    if (!(dt > 0) || dt > max_gap) continue;
    const double a = residuals[k - 1].r, b = residuals[k].r;
    if (!(std::abs(a) <= bound && std::abs(b) <= bound)) continue;
    rr += a * b;
    aa += a * a;
    bb += b * b;
    dts.push_back(dt);
  }
  out.pairs = static_cast<int>(dts.size());
  if (out.pairs < 20 || !(aa > 0 && bb > 0)) {
    out.pairs = 0;
    return out;
  }
  out.lag_one_raw = rr / std::sqrt(aa * bb);
  out.lag_one = out.lag_one_raw;
  if (fitted_parameters > 0 && out.lag_one_raw < 0.999) {
    // The fit's projection allowed for (see the header): rho from
    // lag_one_raw = (n rho - p kappa(rho)) / (n - p kappa(rho)) - 2 rho / n, by fixed point (its
    // slope is about p / n).
    const double n = out.pairs, p = fitted_parameters;
    double rho = out.lag_one_raw;
    for (int i = 0; i < 50; ++i) {
      const double kappa = (1 + rho) / std::max(1 - rho, 1e-3);
      const double next =
          std::min(0.999, (out.lag_one_raw * (n - p * kappa) + p * kappa) / n + 2 * rho / n);
      if (std::abs(next - rho) < 1e-12) break;
      rho = next;
    }
    out.lag_one = rho;
  }
  out.threshold = std::max(min_lag_one, sigmas / std::sqrt(static_cast<double>(out.pairs)));
  if (!(out.lag_one > out.threshold) || out.lag_one >= 0.999) return out;
  // tau with mean exp(-dt / tau) = lag_one: the mean rises with tau; bisection on log tau.
  const auto mean_at = [&](double tau) {
    double s = 0;
    for (double dt : dts) s += std::exp(-dt / tau);
    return s / static_cast<double>(dts.size());
  };
  double lo = std::log(out.spacing_s * 1e-3), hi = std::log(out.spacing_s * 1e4);
  for (int i = 0; i < 100; ++i) {
    const double mid = 0.5 * (lo + hi);
    (mean_at(std::exp(mid)) < out.lag_one ? lo : hi) = mid;
  }
  out.tau_s = std::exp(0.5 * (lo + hi));
  return out;
}

CorrelatedChain MotionChain(const std::vector<FreeTerm>& terms, const FreeData& data,
                            double tau_s) {
  CorrelatedChain chain;
  chain.tau_s = tau_s;
  int row = 0;
  for (const FreeTerm& t : terms) {
    const int k = t.cost->num_residuals();
    const bool in_motion = t.interval >= 0 &&
                           t.interval < static_cast<int>(data.intervals.size()) &&
                           data.intervals[static_cast<std::size_t>(t.interval)].in_motion;
    if (in_motion && k == 1) {
      chain.rows.push_back(row);
      chain.t_s.push_back(t.window.mid_s());
    }
    row += k;
  }
  return chain;
}

std::vector<MotionResidual> ChainResiduals(const CorrelatedChain& chain, const Eigen::VectorXd& r) {
  std::vector<MotionResidual> out;
  out.reserve(chain.rows.size());
  for (std::size_t k = 0; k < chain.rows.size(); ++k)
    out.push_back({chain.t_s[k], r[chain.rows[k]]});
  return out;
}

namespace {

// The chain's members in time order (indices into rows / t_s).
std::vector<std::size_t> TimeOrder(const CorrelatedChain& chain) {
  std::vector<std::size_t> order(chain.rows.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return chain.t_s[a] < chain.t_s[b]; });
  return order;
}

}  // namespace

void AddChainCovariance(const CorrelatedChain& chain, Eigen::MatrixXd* S) {
  if (!(chain.tau_s > 0)) return;
  const std::vector<std::size_t> order = TimeOrder(chain);
  for (std::size_t a = 0; a < order.size(); ++a) {
    for (std::size_t b = a + 1; b < order.size(); ++b) {
      const double dt = chain.t_s[order[b]] - chain.t_s[order[a]];
      const double c = std::exp(-dt / chain.tau_s);
      if (c < 1e-12) break;  // later members are further still
      const int i = chain.rows[order[a]], j = chain.rows[order[b]];
      (*S)(i, j) += c;
      (*S)(j, i) += c;
    }
  }
}

double ChainChi2DofShare(const CorrelatedChain& chain, int m) {
  if (!(chain.tau_s > 0) || m <= 0) return 1.0;
  // a_k = sum_{j < k} rho_jk^2 along the time order: rho_jk = rho_{j,k-1} phi_k, so
  // a_k = phi_k^2 (1 + a_{k-1}).
  const std::vector<std::size_t> order = TimeOrder(chain);
  double a = 0, pairs = 0;
  for (std::size_t k = 1; k < order.size(); ++k) {
    const double dt = chain.t_s[order[k]] - chain.t_s[order[k - 1]];
    const double phi = std::exp(-std::max(dt, 0.0) / chain.tau_s);
    a = phi * phi * (1 + a);
    pairs += a;
  }
  const double md = m;
  return md / (md + 2 * pairs);
}

Eigen::MatrixXd ChainWhitener(int m, const CorrelatedChain& chain) {
  Eigen::MatrixXd W = Eigen::MatrixXd::Identity(m, m);
  if (!(chain.tau_s > 0)) return W;
  const std::vector<std::size_t> order = TimeOrder(chain);
  for (std::size_t k = 1; k < order.size(); ++k) {
    const double dt = chain.t_s[order[k]] - chain.t_s[order[k - 1]];
    const double phi = std::exp(-std::max(dt, 0.0) / chain.tau_s);
    // Two values at one instant would be one: keep phi below 1 so that W stays finite.
    const double scale = 1.0 / std::sqrt(std::max(1.0 - phi * phi, 1e-12));
    const int i = chain.rows[order[k]], j = chain.rows[order[k - 1]];
    W(i, i) = scale;
    W(i, j) = -phi * scale;
  }
  return W;
}

}  // namespace turncal
