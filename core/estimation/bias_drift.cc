#include "core/estimation/bias_drift.h"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace turncal {

namespace {

// For a stationary kernel k, the double integral of k(t - s) over t in [a2, b2] and s in
// [a1, b1] is G(b2 - a1) - G(a2 - a1) - G(b2 - b1) + G(a2 - b1), G even with G'' = k and
// G(0) = G'(0) = 0, whether or not the windows overlap.
template <typename G>
double DoubleIntegral(const TimeWindow& a, const TimeWindow& b, G g) {
  return g(b.t1_s - a.t0_s) - g(b.t0_s - a.t0_s) - g(b.t1_s - a.t1_s) + g(b.t0_s - a.t1_s);
}

// G for k(x) = exp(-|x| / tau): tau^2 (u - 1 + exp(-u)), u = |x| / tau (series for small u,
// where the closed form cancels).
double GaussMarkovG(double x, double tau) {
  const double u = std::abs(x) / tau;
  if (u < 1e-4) return tau * tau * (u * u / 2 - u * u * u / 6 + u * u * u * u / 24);
  return tau * tau * (u + std::expm1(-u));
}

// G for k(x) = |x|: |x|^3 / 6.
double AbsG(double x) {
  const double a = std::abs(x);
  return a * a * a / 6.0;
}

}  // namespace

bool BiasDrift::IsValid(std::string* error) const {
  if (!(gm_sigma.allFinite() && gm_sigma.minCoeff() >= 0) ||
      !(rw_density.allFinite() && rw_density.minCoeff() >= 0)) {
    if (error) *error = "bias drift sigmas must be finite and >= 0";
    return false;
  }
  if (!(warmup_sigma.allFinite() && warmup_sigma.minCoeff() >= 0) ||
      (warmup_sigma.maxCoeff() > 0 && !(warmup_tau_s > 0 && std::isfinite(warmup_tau_s)))) {
    if (error) *error = "the warm-up sigma must be >= 0 and its time constant > 0";
    return false;
  }
  if (gm_sigma.maxCoeff() > 0 && !(gm_tau_s > 0 && std::isfinite(gm_tau_s))) {
    if (error) *error = "the Gauss-Markov correlation time must be > 0";
    return false;
  }
  return true;
}

double BiasDrift::HalvesDifferenceVariance(int axis, double first_s, double second_s) const {
  if (!(first_s > 0) || !(second_s > 0)) return 0.0;
  BiasDrift wander = *this;
  wander.warmup_sigma.setZero();
  const TimeWindow a{0.0, first_s}, b{first_s, first_s + second_s};
  const double v = wander.WindowCovariance(axis, a, a, 0.0) +
                   wander.WindowCovariance(axis, b, b, 0.0) -
                   2.0 * wander.WindowCovariance(axis, a, b, 0.0);
  return std::max(0.0, v);
}

double BiasDrift::WindowCovariance(int axis, const TimeWindow& a, const TimeWindow& b,
                                   double origin_s) const {
  const double ta = std::max(a.duration_s(), 1e-6), tb = std::max(b.duration_s(), 1e-6);
  const TimeWindow wa{a.t0_s, a.t0_s + ta}, wb{b.t0_s, b.t0_s + tb};
  double c = 0.0;
  const double s = gm_sigma[axis];
  if (s > 0) {
    const double tau = gm_tau_s;
    c += s * s * DoubleIntegral(wa, wb, [tau](double x) { return GaussMarkovG(x, tau); }) /
         (ta * tb);
  }
  const double q = rw_density[axis];
  if (q > 0) {
    // min(t, s) = (t + s - |t - s|) / 2, times from origin_s.
    const double mean_sum = (wa.mid_s() - origin_s) + (wb.mid_s() - origin_s);
    c += q * q * (0.5 * mean_sum - 0.5 * DoubleIntegral(wa, wb, AbsG) / (ta * tb));
  }
  const double w = warmup_sigma[axis];
  if (w > 0) {
    // A e^{-(t - o) / T_w} with A ~ N(0, w^2): the product of the windows' mean decays.
    const double o = std::isfinite(warmup_origin_s) ? warmup_origin_s : origin_s;
    c += w * w * WarmupMean(wa, o) * WarmupMean(wb, o);
  }
  return c;
}

double BiasDrift::WarmupMean(const TimeWindow& window, double origin_s) const {
  const double T = std::max(window.duration_s(), 1e-6);
  const double tw = warmup_tau_s;
  return tw / T *
         (std::exp(-(window.t0_s - origin_s) / tw) - std::exp(-(window.t0_s + T - origin_s) / tw));
}

double BiasDrift::VarianceSince(int axis, const TimeWindow& ref, double t_s) const {
  // Var(u(t)) - 2 Cov(u(t), ubar_ref) + Var(ubar_ref), the covariance of the point value with the
  // window's mean by the antiderivatives of the kernels.
  const double T = std::max(ref.duration_s(), 1e-6);
  const double a = ref.t0_s - t_s, b = ref.t0_s + T - t_s;  // the window relative to t
  double v = 0.0;
  const double s = gm_sigma[axis];
  if (s > 0) {
    const double tau = gm_tau_s;
    // Antiderivative of exp(-|x| / tau): odd, sign(x) tau (1 - exp(-|x| / tau)).
    const auto H = [tau](double x) {
      return (x < 0 ? -1.0 : 1.0) * tau * -std::expm1(-std::abs(x) / tau);
    };
    const double cov = s * s * (H(b) - H(a)) / T;
    v += s * s - 2 * cov;
  }
  const double q = rw_density[axis];
  if (q > 0) {
    // Times from the earlier of t and the window's start; min(t, s) = (t + s - |t - s|) / 2 and
    // the antiderivative of |x| is x |x| / 2.
    const double origin = std::min(ref.t0_s, t_s);
    const double t = t_s - origin, mid = ref.mid_s() - origin;
    const auto A = [](double x) { return 0.5 * x * std::abs(x); };
    const double cov = q * q * (0.5 * (t + mid) - 0.5 * (A(b) - A(a)) / T);
    v += q * q * t - 2 * cov;
  }
  const double w = warmup_sigma[axis];
  if (w > 0 && std::isfinite(warmup_origin_s)) {
    // The warm-up's own variance at t, less twice its covariance with the window, is added with
    // the window's variance below.
    const double at = std::exp(-(t_s - warmup_origin_s) / warmup_tau_s);
    v += w * w * (at * at - 2 * at * WarmupMean(ref, warmup_origin_s));
  }
  v += WindowCovariance(axis, ref, ref, std::min(ref.t0_s, t_s));
  return std::max(v, 0.0);
}

Eigen::Vector3d BiasDrift::SigmaAfter(const TimeWindow& ref, double seconds) const {
  Eigen::Vector3d out;
  for (int axis = 0; axis < 3; ++axis) {
    out[axis] = std::sqrt(VarianceSince(axis, ref, ref.t1_s + std::max(seconds, 0.0)));
  }
  return out;
}

std::vector<int> TimeOrder(const std::vector<TimeWindow>& windows) {
  std::vector<int> order(windows.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return windows[static_cast<std::size_t>(a)].t0_s < windows[static_cast<std::size_t>(b)].t0_s;
  });
  return order;
}

Eigen::MatrixXd DriftIncrementCovariance(const BiasDrift& drift, int axis,
                                         const std::vector<TimeWindow>& windows, int ref) {
  const int n = static_cast<int>(windows.size());
  Eigen::MatrixXd K(n, n);
  double origin = windows.empty() ? 0.0 : windows[0].t0_s;
  for (const auto& w : windows) origin = std::min(origin, w.t0_s);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j <= i; ++j)
      K(i, j) = K(j, i) = drift.WindowCovariance(axis, windows[i], windows[j], origin);
  Eigen::MatrixXd D(n, n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) D(i, j) = K(i, j) - K(i, ref) - K(ref, j) + K(ref, ref);
  D.row(ref).setZero();
  D.col(ref).setZero();
  return D;
}

}  // namespace turncal
