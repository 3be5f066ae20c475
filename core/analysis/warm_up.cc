#include "core/analysis/warm_up.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

namespace turncal {

BinnedMeans::BinnedMeans(double bin_s, int max_bins)
    : bin_s_(bin_s > 0 ? bin_s : 1.0), max_bins_(std::max(16, max_bins & ~1)) {}

void BinnedMeans::Add(double t_s, const Eigen::Vector3d& v) {
  if (!(t_s >= 0) || !v.allFinite()) return;
  auto index = static_cast<std::size_t>(t_s / bin_s_);
  while (index >= static_cast<std::size_t>(max_bins_)) {
    Merge();
    index = static_cast<std::size_t>(t_s / bin_s_);
  }
  if (index >= count_.size()) {
    sum_.resize(index + 1, Eigen::Vector3d::Zero());
    count_.resize(index + 1, 0);
  }
  sum_[index] += v;
  ++count_[index];
}

void BinnedMeans::Merge() {
  const std::size_t half = (count_.size() + 1) / 2;
  for (std::size_t i = 0; i < half; ++i) {
    const std::size_t a = 2 * i, b = 2 * i + 1;
    sum_[i] = sum_[a] + (b < sum_.size() ? sum_[b] : Eigen::Vector3d::Zero());
    count_[i] = count_[a] + (b < count_.size() ? count_[b] : 0);
  }
  sum_.resize(half);
  count_.resize(half);
  bin_s_ *= 2;
}

void BinnedMeans::Series(int axis, std::vector<double>* t_s, std::vector<double>* mean) const {
  t_s->clear();
  mean->clear();
  // The last bin is usually partial: its centre is not its samples' mean time, so it is left out
  // unless it is the only one.
  const std::size_t n = count_.size() > 1 ? count_.size() - 1 : count_.size();
  for (std::size_t i = 0; i < n; ++i) {
    if (count_[i] == 0) continue;
    t_s->push_back((static_cast<double>(i) + 0.5) * bin_s_);
    mean->push_back(sum_[i][axis] / static_cast<double>(count_[i]));
  }
}

BinNoiseModel BinNoiseFromIeee(const IeeeNoiseFit& ieee, double bin_s, double span_s) {
  BinNoiseModel m;
  if (!ieee.ok) return m;
  m.white = ieee.terms[kIeeeN].value;
  m.gauss_markov = FlickerAsGaussMarkov(ieee.terms[kIeeeB].value, bin_s / 10.0, 100.0 * span_s);
  m.random_walk = ieee.terms[kIeeeK].value;
  return m;
}

namespace {

// 1 - (1 - e^-x) / x without its cancellation for small x.
double OneMinusMeanDecay(double x) {
  if (x < 1e-3) return x / 2 - x * x / 6 + x * x * x / 24;
  return 1.0 - (-std::expm1(-x)) / x;
}

// The covariance of means over bins `bin_s` long centred at t (seconds from switch-on).
Eigen::MatrixXd BinCovariance(const std::vector<double>& t, double bin_s,
                              const BinNoiseModel& noise) {
  const int n = static_cast<int>(t.size());
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(n, n);
  for (int i = 0; i < n; ++i) {
    const double ti = t[static_cast<std::size_t>(i)];
    c(i, i) += noise.white * noise.white / bin_s;
    for (int j = 0; j <= i; ++j) {
      const double tj = t[static_cast<std::size_t>(j)];
      double v = 0;
      // The rate random walk from switch-on: the mean of min(u, v) over the two bins.
      const double k2 = noise.random_walk * noise.random_walk;
      v += i == j ? k2 * (ti - bin_s / 6.0) : k2 * std::min(ti, tj);
      for (const GaussMarkovPole& p : noise.gauss_markov) {
        const double x = bin_s / p.tau_s;
        if (i == j) {
          v += p.variance * 2.0 / x * OneMinusMeanDecay(x);
        } else {
          const double lag = std::fabs(ti - tj);
          const double f = -std::expm1(-x) / x;
          v += p.variance * f * f * std::exp(-(lag - bin_s) / p.tau_s);
        }
      }
      c(i, j) += v;
      if (i != j) c(j, i) += v;
    }
  }
  const double nugget = 1e-12 * c.diagonal().maxCoeff();
  for (int i = 0; i < n; ++i) c(i, i) += nugget;
  return c;
}

struct LinearAtTau {
  double settled = 0.0, amplitude = 0.0, rss = INFINITY;
};

// The series whitened: y, the constant and, per tau, the decay, each multiplied by L^-1 (C = L
// L'); the identity without a noise model.
class Whitener {
 public:
  Whitener(const std::vector<double>& t, const std::vector<double>& y, double bin_s,
           const BinNoiseModel* noise)
      : t_(t) {
    const int n = static_cast<int>(t.size());
    if (noise) {
      llt_.compute(BinCovariance(t, bin_s, *noise));
      ok_ = llt_.info() == Eigen::Success;
      modelled_ = true;
    }
    y_ = Apply(Eigen::Map<const Eigen::VectorXd>(y.data(), n));
    one_ = Apply(Eigen::VectorXd::Ones(n));
  }
  bool ok() const { return ok_; }
  bool modelled() const { return modelled_; }
  Eigen::VectorXd Apply(const Eigen::VectorXd& v) const {
    return modelled_ ? Eigen::VectorXd(llt_.matrixL().solve(v)) : v;
  }
  Eigen::VectorXd Decay(double tau) const {
    Eigen::VectorXd e(static_cast<int>(t_.size()));
    for (int k = 0; k < e.size(); ++k) e[k] = std::exp(-t_[static_cast<std::size_t>(k)] / tau);
    return e;
  }
  LinearAtTau Solve(double tau) const {
    const Eigen::VectorXd e = Apply(Decay(tau));
    const double s0 = one_.squaredNorm(), s1 = one_.dot(e), s11 = e.squaredNorm();
    const double sy = one_.dot(y_), s1y = e.dot(y_);
    const double det = s0 * s11 - s1 * s1;
    LinearAtTau r;
    if (!(det > 1e-12 * s0 * s11)) return r;
    r.settled = (s11 * sy - s1 * s1y) / det;
    r.amplitude = (s0 * s1y - s1 * sy) / det;
    r.rss = (y_ - r.settled * one_ - r.amplitude * e).squaredNorm();
    return r;
  }

 private:
  const std::vector<double>& t_;
  Eigen::LLT<Eigen::MatrixXd> llt_;
  bool ok_ = true, modelled_ = false;
  Eigen::VectorXd y_, one_;
};

}  // namespace

WarmUpFit FitWarmUp(const std::vector<double>& t_s, const std::vector<double>& mean, double bin_s,
                    double threshold, const BinNoiseModel* noise) {
  WarmUpFit fit;
  const int given = static_cast<int>(std::min(t_s.size(), mean.size()));
  fit.threshold = threshold;
  if (given < 8) {
    fit.bins = given;
    fit.error = "fewer than 8 bins: too short for a warm-up transient";
    return fit;
  }
  if (!(threshold > 0) || !(bin_s > 0)) {
    fit.error = "no threshold for the warm-up time";
    return fit;
  }
  // At most 400 bins: neighbours merged (the covariance is a dense n x n matrix).
  constexpr int kMaxBins = 400;
  const int merge = (given + kMaxBins - 1) / kMaxBins;
  std::vector<double> t, y;
  for (int k = 0; k + merge <= given; k += merge) {
    double st = 0, sy = 0;
    for (int i = k; i < k + merge; ++i) {
      st += t_s[static_cast<std::size_t>(i)];
      sy += mean[static_cast<std::size_t>(i)];
    }
    t.push_back(st / merge);
    y.push_back(sy / merge);
  }
  bin_s *= merge;
  const int n = static_cast<int>(t.size());
  fit.bins = n;
  fit.span_s = t.back() + 0.5 * bin_s;
  const Whitener w(t, y, bin_s, noise);
  if (!w.ok()) {
    fit.error = "the bins' covariance is not positive definite";
    return fit;
  }
  fit.modelled = w.modelled();
  // tau on a log grid from half the first bin's centre to three spans, then golden section.
  const double lo = std::log(0.5 * t.front()), hi = std::log(3.0 * fit.span_s);
  constexpr int kGrid = 80;
  int best = 0;
  double best_rss = INFINITY;
  for (int i = 0; i <= kGrid; ++i) {
    const double r = w.Solve(std::exp(lo + (hi - lo) * i / kGrid)).rss;
    if (r < best_rss) best_rss = r, best = i;
  }
  double a = lo + (hi - lo) * std::max(0, best - 1) / kGrid;
  double b = lo + (hi - lo) * std::min(kGrid, best + 1) / kGrid;
  const double golden = 0.5 * (std::sqrt(5.0) - 1.0);
  for (int it = 0; it < 60; ++it) {
    const double c = b - golden * (b - a), d = a + golden * (b - a);
    if (w.Solve(std::exp(c)).rss < w.Solve(std::exp(d)).rss) {
      b = d;
    } else {
      a = c;
    }
  }
  const double tau = std::exp(0.5 * (a + b));
  const LinearAtTau at = w.Solve(tau);
  if (!std::isfinite(at.rss)) {
    fit.error = "the transient could not be fitted";
    return fit;
  }
  fit.settled = at.settled;
  fit.amplitude = at.amplitude;
  fit.tau_s = tau;
  const double dof = n - 3;
  fit.chi2 = at.rss;
  double scale2 = 1.0;  // what the Fisher information's covariance is multiplied by
  std::vector<double> res(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k)
    res[static_cast<std::size_t>(k)] =
        y[static_cast<std::size_t>(k)] - at.settled -
        at.amplitude * std::exp(-t[static_cast<std::size_t>(k)] / tau);
  double c0 = 0, c1 = 0;
  for (int k = 0; k < n; ++k) {
    c0 += res[static_cast<std::size_t>(k)] * res[static_cast<std::size_t>(k)];
    if (k > 0) c1 += res[static_cast<std::size_t>(k)] * res[static_cast<std::size_t>(k - 1)];
  }
  fit.bin_sigma = std::sqrt(c0 / dof);
  if (fit.modelled) {
    scale2 = std::max(1.0, at.rss / dof);
  } else {
    // The residuals hold the bias's own wander, correlated from bin to bin: the sigma are widened
    // as for an AR(1) series with the residuals' lag-one correlation.
    const double rho = c0 > 0 ? std::clamp(c1 / c0, 0.0, 0.95) : 0.0;
    scale2 = fit.bin_sigma * fit.bin_sigma * (1 + rho) / (1 - rho);
  }
  Eigen::MatrixXd J(n, 3);
  const Eigen::VectorXd decay = w.Decay(tau);
  Eigen::VectorXd d_tau(n);
  for (int k = 0; k < n; ++k)
    d_tau[k] = at.amplitude * t[static_cast<std::size_t>(k)] / (tau * tau) * decay[k];
  J.col(0) = w.Apply(Eigen::VectorXd::Ones(n));
  J.col(1) = w.Apply(decay);
  J.col(2) = w.Apply(d_tau);
  const Eigen::Matrix3d info = J.transpose() * J;
  const Eigen::Matrix3d cov = info.ldlt().solve(Eigen::Matrix3d::Identity()) * scale2;
  fit.settled_sigma = std::sqrt(std::max(0.0, cov(0, 0)));
  fit.amplitude_sigma = std::sqrt(std::max(0.0, cov(1, 1)));
  fit.tau_sigma = std::sqrt(std::max(0.0, cov(2, 2)));
  fit.ok = true;
  // A transient: the amplitude 3 sigma from zero, and it settles within the recording.
  fit.resolved = std::isfinite(fit.amplitude_sigma) &&
                 std::fabs(at.amplitude) > 3.0 * fit.amplitude_sigma && tau < fit.span_s;
  if (fit.resolved) {
    const double ratio = std::fabs(at.amplitude) / threshold;
    if (ratio > 1) {
      const double l = std::log(ratio);
      fit.time_s = tau * l;
      // d t / d tau = ln ratio, d t / d amplitude = tau / amplitude.
      const double g_tau = l, g_amp = tau / at.amplitude;
      fit.time_sigma =
          std::sqrt(std::max(0.0, g_tau * g_tau * cov(2, 2) + g_amp * g_amp * cov(1, 1) +
                                      2 * g_tau * g_amp * cov(1, 2)));
    }
  }
  return fit;
}

}  // namespace turncal
