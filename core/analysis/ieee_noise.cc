#include "core/analysis/ieee_noise.h"

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <unordered_map>

namespace turncal {

namespace {

using Real = long double;
constexpr int kRandomTerms = 4;  // Q, N, B, K; the ramp R is a mean

// The generalised autocovariance of the integrated rate X (X_k = sum of the samples up to k) of
// each random term, at a lag of t samples, up to the factor Kappa() fixes.
Real Sx(int term, Real t) {
  const Real a = std::fabs(t);
  switch (term) {
    case kIeeeQ:  // white angle: X is white
      return a == 0 ? 1 : 0;
    case kIeeeN:  // white rate: X a random walk
      return -a;
    case kIeeeB:  // flicker rate
      return a == 0 ? 0 : t * t * std::log(a);
    default:  // random-walk rate: X an integrated random walk
      return a * a * a;
  }
}

constexpr Real kC[3] = {1, -2, 1};
constexpr Real kUniformKurtosis = -1.2L;  // excess kurtosis of a uniform distribution

// The covariance of the Allan differences (X[2 m1] - 2 X[m1] + X[0]) and the one of m2 starting
// `lag` samples later, up to the factor m1 m2 Kappa(term).
Real RawCov(int term, Real m1, Real m2, Real lag) {
  Real c = 0;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) c += kC[a] * kC[b] * Sx(term, lag + b * m2 - a * m1);
  return c;
}

// The factor that makes a term's raw Allan variance (RawCov at lag 0 / (2 m^2)) its IEEE one
// for a coefficient of 1: exact power laws, so one cluster size fixes it.
double Kappa(int term, double dt_s) {
  constexpr Real m = 64;
  const Real raw = RawCov(term, m, m, 0) / (2 * m * m);
  return static_cast<double>(IeeeUnitAvar(term, static_cast<double>(m) * dt_s) / raw);
}

// For one pair of cluster sizes: the sums that make the covariance of their Allan variances
// quadratic in theta: cov = sum_kl theta_k theta_l I[k][l] + theta_R tau1 tau2 sum_k theta_k J[k].
struct PairSums {
  double I[kRandomTerms][kRandomTerms] = {};
  double J[kRandomTerms] = {};
};

PairSums SumPair(std::int64_t m1, std::int64_t m2, double dt_s, std::int64_t n,
                 const std::array<double, kRandomTerms>& kappa) {
  PairSums s;
  const std::int64_t big_m1 = n - 2 * m1 + 1, big_m2 = n - 2 * m2 + 1;
  if (big_m1 < 1 || big_m2 < 1) return s;
  const Real rm1 = static_cast<Real>(m1), rm2 = static_cast<Real>(m2);
  // Pairs (i, j) of starting points with j - i = lag.
  auto count = [&](Real lag) -> Real {
    const Real lo = std::max<Real>(0, -lag);
    const Real hi = std::min<Real>(static_cast<Real>(big_m1), static_cast<Real>(big_m2) - lag);
    return std::max<Real>(0, hi - lo);
  };
  Real I[kRandomTerms][kRandomTerms] = {}, J[kRandomTerms] = {};
  // Quantisation is uniform, not Gaussian: its fourth cumulant adds kUniformKurtosis times the
  // sum over the samples both differences hold of the squares of their weights.
  const Real q_weight = static_cast<Real>(kappa[kIeeeQ]) / (rm1 * rm2);
  auto add = [&](Real lag, Real weight, bool integer_lags) {
    const Real w = weight * count(lag);
    if (w == 0) return;
    if (integer_lags) {
      Real fourth = 0;
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
          if (lag + b * rm2 - a * rm1 == 0) fourth += kC[a] * kC[a] * kC[b] * kC[b];
      I[kIeeeQ][kIeeeQ] += w * kUniformKurtosis * q_weight * q_weight * fourth / 2;
    }
    Real c[kRandomTerms];
    for (int k = 0; k < kRandomTerms; ++k) {
      c[k] = (k == kIeeeQ && !integer_lags)
                 ? 0
                 : RawCov(k, rm1, rm2, lag) * static_cast<Real>(kappa[static_cast<size_t>(k)]) /
                       (rm1 * rm2);
    }
    for (int k = 0; k < kRandomTerms; ++k) {
      J[k] += w * c[k];
      for (int l = 0; l < kRandomTerms; ++l) I[k][l] += w * c[k] * c[l];
    }
  };
  // The differences are correlated while their spans overlap, flicker's a little beyond.
  const std::int64_t pad = 2 * std::max(m1, m2);
  const std::int64_t from = -2 * m2 - pad, to = 2 * m1 + pad;
  if (to - from <= 1024) {
    for (std::int64_t lag = from; lag <= to; ++lag) add(static_cast<Real>(lag), 1, true);
  } else {
    // Simpson's rule between the kinks (lag = a m1 - b m2), where the covariance is smooth. The
    // quantisation term is negligible at these cluster sizes and left out.
    std::vector<Real> knots = {static_cast<Real>(from), static_cast<Real>(to)};
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) knots.push_back(a * rm1 - b * rm2);
    std::sort(knots.begin(), knots.end());
    constexpr int kSteps = 48;  // even
    for (std::size_t q = 0; q + 1 < knots.size(); ++q) {
      const Real lo = knots[q], hi = knots[q + 1];
      if (!(hi > lo)) continue;
      const Real h = (hi - lo) / kSteps;
      for (int i = 0; i <= kSteps; ++i) {
        const Real w = (i == 0 || i == kSteps) ? 1 : (i % 2 == 1 ? 4 : 2);
        add(lo + h * i, w * h / 3, false);
      }
    }
  }
  const Real norm = 4 * static_cast<Real>(big_m1) * static_cast<Real>(big_m2);
  const Real tau_product = static_cast<Real>(m1) * static_cast<Real>(m2) * dt_s * dt_s;
  for (int k = 0; k < kRandomTerms; ++k) {
    s.J[k] = static_cast<double>(4 * tau_product * J[k] / norm);
    for (int l = 0; l < kRandomTerms; ++l) s.I[k][l] = static_cast<double>(2 * I[k][l] / norm);
  }
  return s;
}

// The pair sums depend only on (m1, m2, dt, n), so the axes of a triad (and the repeated fits of
// one recording) share them: a memo per thread, cleared when it grows past a few thousand pairs
// (each about 200 bytes).
struct PairKey {
  std::int64_t m1, m2, n;
  std::uint64_t dt_bits;
  bool operator==(const PairKey& o) const {
    return m1 == o.m1 && m2 == o.m2 && n == o.n && dt_bits == o.dt_bits;
  }
};
struct PairKeyHash {
  std::size_t operator()(const PairKey& k) const {
    std::uint64_t h = 1469598103934665603ULL;
    for (std::uint64_t v : {static_cast<std::uint64_t>(k.m1), static_cast<std::uint64_t>(k.m2),
                            static_cast<std::uint64_t>(k.n), k.dt_bits})
      h = (h ^ v) * 1099511628211ULL;
    return static_cast<std::size_t>(h);
  }
};

const PairSums& SharedPairSums(std::int64_t m1, std::int64_t m2, double dt_s, std::int64_t n,
                               const std::array<double, kRandomTerms>& kappa) {
  thread_local std::unordered_map<PairKey, PairSums, PairKeyHash> memo;
  std::uint64_t dt_bits = 0;
  std::memcpy(&dt_bits, &dt_s, sizeof dt_bits);
  const PairKey key{m1, m2, n, dt_bits};
  if (auto it = memo.find(key); it != memo.end()) return it->second;
  if (memo.size() >= 8192) memo.clear();
  return memo.emplace(key, SumPair(m1, m2, dt_s, n, kappa)).first->second;
}

double Covariance(const PairSums& s, const std::array<double, kIeeeTerms>& theta) {
  double v = 0;
  for (int k = 0; k < kRandomTerms; ++k) {
    const double tk = theta[static_cast<size_t>(k)];
    v += theta[kIeeeR] * tk * s.J[k];
    for (int l = 0; l < kRandomTerms; ++l) v += tk * theta[static_cast<size_t>(l)] * s.I[k][l];
  }
  return v;
}

std::array<double, kRandomTerms> Kappas(double dt_s) {
  std::array<double, kRandomTerms> kappa{};
  for (int k = 0; k < kRandomTerms; ++k) kappa[static_cast<size_t>(k)] = Kappa(k, dt_s);
  return kappa;
}

// The non-negative least squares of ||y - A theta|| by every subset of the columns (five
// columns: 31 subsets): the best whose unconstrained solution is non-negative.
Eigen::VectorXd SubsetNnls(const Eigen::MatrixXd& A, const Eigen::VectorXd& y, double* cost) {
  const int cols = static_cast<int>(A.cols());
  Eigen::VectorXd best = Eigen::VectorXd::Zero(cols);
  double best_cost = y.squaredNorm();
  for (int mask = 1; mask < (1 << cols); ++mask) {
    std::vector<int> use;
    for (int c = 0; c < cols; ++c)
      if (mask & (1 << c)) use.push_back(c);
    if (static_cast<int>(use.size()) > A.rows()) continue;
    Eigen::MatrixXd Ac(A.rows(), static_cast<int>(use.size()));
    for (std::size_t c = 0; c < use.size(); ++c) Ac.col(static_cast<int>(c)) = A.col(use[c]);
    const Eigen::VectorXd coef = Ac.colPivHouseholderQr().solve(y);
    if (!coef.allFinite() || coef.minCoeff() < 0) continue;
    const double c = (Ac * coef - y).squaredNorm();
    if (c < best_cost) {
      best_cost = c;
      best.setZero();
      for (std::size_t k = 0; k < use.size(); ++k) best[use[k]] = coef[static_cast<int>(k)];
    }
  }
  *cost = best_cost;
  return best;
}

}  // namespace

const char* IeeeTermName(int term) {
  static const char* const kNames[] = {"Q", "N", "B", "K", "R"};
  return term >= 0 && term < kIeeeTerms ? kNames[term] : "?";
}

IeeeUnit IeeeTermUnit(const std::string& triad, int term) {
  constexpr double kDeg = 180.0 / M_PI, kUg = 1e6 / 9.80665;
  // Q, N, B, K, R.
  static const IeeeUnit kGyr[] = {{"rad", "arcsec", kDeg * 3600},
                                  {"rad/s/sqrt(Hz)", "deg/sqrt(h)", kDeg * 60},
                                  {"rad/s", "deg/h", kDeg * 3600},
                                  {"rad/s/sqrt(s)", "deg/h/sqrt(h)", kDeg * 3600 * 60},
                                  {"rad/s^2", "deg/h^2", kDeg * 3600 * 3600}};
  static const IeeeUnit kAcc[] = {{"m/s", "mm/s", 1e3},
                                  {"m/s^2/sqrt(Hz)", "ug/sqrt(Hz)", kUg},
                                  {"m/s^2", "ug", kUg},
                                  {"m/s^2/sqrt(s)", "ug/sqrt(h)", kUg * 60},
                                  {"m/s^3", "ug/h", kUg * 3600}};
  static const IeeeUnit kMag[] = {{"G*s", "mG*s", 1e3},
                                  {"G/sqrt(Hz)", "mG/sqrt(Hz)", 1e3},
                                  {"G", "mG", 1e3},
                                  {"G/sqrt(s)", "mG/sqrt(h)", 1e3 * 60},
                                  {"G/s", "mG/h", 1e3 * 3600}};
  const int k = std::clamp(term, 0, kIeeeTerms - 1);
  return triad == "gyr" ? kGyr[k] : triad == "acc" ? kAcc[k] : kMag[k];
}

double IeeeUnitAvar(int term, double tau_s) {
  switch (term) {
    case kIeeeQ:
      return 3.0 / (tau_s * tau_s);
    case kIeeeN:
      return 1.0 / tau_s;
    case kIeeeB:
      return 2.0 * std::log(2.0) / M_PI;
    case kIeeeK:
      return tau_s / 3.0;
    default:
      return tau_s * tau_s / 2.0;
  }
}

double IeeeNoiseFit::Adev(double tau_s) const {
  double v = 0;
  for (int k = 0; k < kIeeeTerms; ++k) {
    const double c = terms[static_cast<size_t>(k)].value;
    v += c * c * IeeeUnitAvar(k, tau_s);
  }
  return std::sqrt(v);
}

std::vector<GaussMarkovPole> FlickerAsGaussMarkov(double b, double shortest_tau_s,
                                                  double longest_tau_s) {
  // Correlation times tau_i = shortest r^i, each of variance s^2: the sum's one-sided spectrum
  // sum 4 s^2 tau_i / (1 + (2 pi f tau_i)^2) is s^2 / (f ln r) between the ends, which is
  // IEEE 952's two-sided B^2 / (2 pi f) (one-sided: B^2 / (pi f)) for s^2 = B^2 ln r / pi.
  std::vector<GaussMarkovPole> poles;
  if (!(b > 0) || !(shortest_tau_s > 0)) return poles;
  const double ratio = std::pow(10.0, 1.0 / 3.0);
  const double variance = b * b * std::log(ratio) / M_PI;
  for (double tau = shortest_tau_s; tau < longest_tau_s * ratio; tau *= ratio)
    poles.push_back({tau, variance});
  return poles;
}

double AvarCovariance(std::int64_t m1, std::int64_t m2, double dt_s, std::int64_t n,
                      const std::array<double, kIeeeTerms>& theta) {
  return Covariance(SumPair(m1, m2, dt_s, n, Kappas(dt_s)), theta);
}

IeeeNoiseFit FitIeeeNoise(const std::vector<IeeeAvarPoint>& points, double dt_s, std::int64_t n,
                          bool independent) {
  IeeeNoiseFit fit;
  if (!(dt_s > 0) || n < 18) {
    fit.error = "too few samples for the IEEE terms";
    return fit;
  }
  std::vector<IeeeAvarPoint> use;
  for (const IeeeAvarPoint& p : points) {
    if (p.m < 1 || 9 * p.m > n || !(p.avar > 0) || !std::isfinite(p.avar)) continue;
    if (!use.empty() && static_cast<double>(p.m) < 1.5 * static_cast<double>(use.back().m))
      continue;
    use.push_back(p);
  }
  const int rows = static_cast<int>(use.size());
  if (rows < 3) {
    fit.error = "fewer than three Allan variances with nine clusters";
    return fit;
  }
  fit.points = rows;
  fit.tau_min_s = static_cast<double>(use.front().m) * dt_s;
  fit.tau_max_s = static_cast<double>(use.back().m) * dt_s;

  const std::array<double, kRandomTerms> kappa = Kappas(dt_s);
  std::vector<PairSums> sums(static_cast<std::size_t>(rows * rows));
  for (int i = 0; i < rows; ++i)
    for (int j = 0; j <= i; ++j) {
      sums[static_cast<size_t>(i * rows + j)] = SharedPairSums(
          use[static_cast<size_t>(i)].m, use[static_cast<size_t>(j)].m, dt_s, n, kappa);
      sums[static_cast<size_t>(j * rows + i)] = sums[static_cast<size_t>(i * rows + j)];
    }
  Eigen::MatrixXd A(rows, kIeeeTerms);
  Eigen::VectorXd y(rows);
  for (int i = 0; i < rows; ++i) {
    const double tau = static_cast<double>(use[static_cast<size_t>(i)].m) * dt_s;
    for (int k = 0; k < kIeeeTerms; ++k) A(i, k) = IeeeUnitAvar(k, tau);
    y[i] = use[static_cast<size_t>(i)].avar;
  }

  // The covariance of the measured variances for theta, with a floor that keeps it positive.
  auto covariance = [&](const Eigen::VectorXd& theta) {
    std::array<double, kIeeeTerms> t{};
    for (int k = 0; k < kIeeeTerms; ++k) t[static_cast<size_t>(k)] = theta[k];
    Eigen::MatrixXd C(rows, rows);
    for (int i = 0; i < rows; ++i)
      for (int j = 0; j < rows; ++j) {
        C(i, j) =
            (independent && i != j) ? 0.0 : Covariance(sums[static_cast<size_t>(i * rows + j)], t);
      }
    for (int i = 0; i < rows; ++i) C(i, i) += 1e-10 * y[i] * y[i];
    return C;
  };
  // Whitened and column-scaled: the terms differ by many orders of magnitude.
  struct Whitened {
    Eigen::MatrixXd A;
    Eigen::VectorXd y, scale;
    bool ok = false;
  };
  auto whiten = [&](const Eigen::MatrixXd& C) {
    Whitened w;
    const Eigen::LLT<Eigen::MatrixXd> llt(C);
    if (llt.info() != Eigen::Success) return w;
    w.A = llt.matrixL().solve(A);
    w.y = llt.matrixL().solve(y);
    w.scale = Eigen::VectorXd(kIeeeTerms);
    for (int k = 0; k < kIeeeTerms; ++k) {
      const double norm = w.A.col(k).norm();
      w.scale[k] = norm > 0 ? 1.0 / norm : 1.0;
      w.A.col(k) *= w.scale[k];
    }
    w.ok = w.A.allFinite() && w.y.allFinite();
    return w;
  };

  // Start: each variance independent with the white-noise scatter of its clusters.
  Eigen::MatrixXd C0 = Eigen::MatrixXd::Zero(rows, rows);
  for (int i = 0; i < rows; ++i) {
    const double clusters =
        static_cast<double>(n) / static_cast<double>(use[static_cast<size_t>(i)].m);
    C0(i, i) = 2.0 * y[i] * y[i] / clusters;
  }
  Whitened w = whiten(C0);
  if (!w.ok) {
    fit.error = "the Allan variances could not be weighted";
    return fit;
  }
  double cost = 0;
  Eigen::VectorXd theta = SubsetNnls(w.A, w.y, &cost).cwiseProduct(w.scale);
  for (int iteration = 0; iteration < 8; ++iteration) {
    if (!(theta.maxCoeff() > 0)) break;
    w = whiten(covariance(theta));
    if (!w.ok) break;
    const Eigen::VectorXd next = SubsetNnls(w.A, w.y, &cost).cwiseProduct(w.scale);
    const double change =
        ((next - theta).array().abs() / (theta.array().abs().max(next.array().abs()) + 1e-300))
            .maxCoeff();
    theta = next;
    if (change < 1e-4) break;
  }
  if (!w.ok || !(theta.maxCoeff() > 0)) {
    fit.error = "the generalised least squares did not converge";
    return fit;
  }
  // Sigma: the Fisher information of the terms left free; a term at zero gets the upper bound
  // of the fit with every term free.
  std::vector<int> free_terms;
  for (int k = 0; k < kIeeeTerms; ++k)
    if (theta[k] > 0) free_terms.push_back(k);
  Eigen::MatrixXd Af(rows, static_cast<int>(free_terms.size()));
  for (std::size_t c = 0; c < free_terms.size(); ++c)
    Af.col(static_cast<int>(c)) = w.A.col(free_terms[c]);
  const Eigen::MatrixXd cov_free =
      (Af.transpose() * Af).ldlt().solve(Eigen::MatrixXd::Identity(Af.cols(), Af.cols()));
  Eigen::VectorXd sigma_theta = Eigen::VectorXd::Zero(kIeeeTerms);
  for (std::size_t c = 0; c < free_terms.size(); ++c) {
    const int k = free_terms[c];
    sigma_theta[k] =
        std::sqrt(std::max(0.0, cov_free(static_cast<int>(c), static_cast<int>(c)))) * w.scale[k];
  }
  Eigen::VectorXd upper_at_zero = Eigen::VectorXd::Constant(kIeeeTerms, INFINITY);
  if (rows >= kIeeeTerms) {
    const Eigen::MatrixXd info = w.A.transpose() * w.A;
    const Eigen::MatrixXd cov_all =
        info.ldlt().solve(Eigen::MatrixXd::Identity(kIeeeTerms, kIeeeTerms));
    const Eigen::VectorXd unconstrained = info.ldlt().solve(w.A.transpose() * w.y);
    for (int k = 0; k < kIeeeTerms; ++k) {
      const double s = std::sqrt(std::max(0.0, cov_all(k, k)));
      if (std::isfinite(s) && std::isfinite(unconstrained[k]))
        upper_at_zero[k] = std::max(0.0, unconstrained[k] + 1.96 * s) * w.scale[k];
    }
  }
  for (int k = 0; k < kIeeeTerms; ++k) {
    IeeeTermEstimate& e = fit.terms[static_cast<size_t>(k)];
    const double t = theta[k], s = sigma_theta[k];
    e.value = std::sqrt(t);
    if (t > 0) {
      e.sigma = s / (2.0 * e.value);
      e.low95 = std::sqrt(std::max(0.0, t - 1.96 * s));
      e.high95 = std::sqrt(t + 1.96 * s);
      e.resolved = t > 2.0 * s;
    } else {
      e.high95 = std::sqrt(upper_at_zero[k]);
    }
  }
  fit.chi2 = cost;
  fit.dof = rows - static_cast<int>(free_terms.size());
  fit.ok = true;
  return fit;
}

}  // namespace turncal
