#include "core/analysis/allan_edf.h"

#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>
#include <limits>

namespace turncal {

namespace {

using Real = long double;

// The generalised autocovariance of the phase's integral for power-law noise of type alpha (up
// to a constant factor, which cancels in the edf).
Real Sw(Real t, int alpha) {
  const Real a = std::fabs(t);
  switch (alpha) {
    case 2:
      return -a;
    case 1:
      return a == 0 ? 0 : t * t * std::log(a);
    case 0:
      return a * a * a;
    case -1:
      return a == 0 ? 0 : t * t * t * t * std::log(a);
    case -2:
      return a * a * a * a * a;
    case -3:
      return a == 0 ? 0 : t * t * t * t * t * t * std::log(a);
    default:
      return a * a * a * a * a * a * a;
  }
}

// The phase's generalised autocovariance at lag t. The rate types' phase is sampled: the
// second derivative of Sw, which is Sw of alpha + 2 up to a factor. The phase types' would have
// no bandwidth: their phase is taken as averaged over one sample (1 / f of tau), which for white
// phase at the sample lags is the sampled phase's.
Real Sx(Real t, Real f, int alpha) {
  if (alpha <= 0) return Sw(t, alpha + 2);
  return f * f * (2 * Sw(t, alpha) - Sw(t - 1 / f, alpha) - Sw(t + 1 / f, alpha));
}

// The autocovariance of the d-th phase differences at lag t (in cluster times).
Real Sz(Real t, Real f, int alpha, int d) {
  static constexpr Real kBinomial[4][4] = {
      {1, 0, 0, 0}, {2, 1, 0, 0}, {6, 4, 1, 0}, {20, 15, 6, 1}};
  Real z = kBinomial[d][0] * Sx(t, f, alpha);
  for (int k = 1; k <= d; ++k) {
    const Real sign = (k % 2 == 1) ? -1 : 1;
    z += sign * kBinomial[d][k] * (Sx(t - k, f, alpha) + Sx(t + k, f, alpha));
  }
  return z;
}

}  // namespace

double OverlappingEdf(int alpha, int d, std::int64_t m, std::int64_t stride, std::int64_t n) {
  alpha = std::clamp(alpha, -2, 2);
  d = std::clamp(d, 1, 3);
  stride = std::max<std::int64_t>(stride, 1);
  if (m < 1 || n < d * m + 1) return 0.0;
  const Real f = static_cast<Real>(m);                              // unaveraged phase: F = m
  const Real s = static_cast<Real>(m) / static_cast<Real>(stride);  // starting points per tau
  const std::int64_t terms = 1 + (n - d * m) / stride;              // M
  const Real big_m = static_cast<Real>(terms);
  const std::int64_t lags =
      std::min<std::int64_t>(terms, static_cast<std::int64_t>((d + 1) * s));  // J
  const Real z0 = Sz(0, f, alpha, d);
  if (!(z0 != 0)) return 0.0;
  auto weight = [&](Real j) { return 1 - j / big_m; };
  auto term = [&](Real j) {
    const Real z = Sz(j / s, f, alpha, d);
    return z * z;
  };
  Real sum = z0 * z0 + weight(static_cast<Real>(lags)) * term(static_cast<Real>(lags));
  constexpr std::int64_t kExactLags = 4000;
  if (alpha == 2) {
    // White phase: the differences are correlated only at whole cluster times (d + 1 of them).
    for (std::int64_t k = 1; k <= d + 1; ++k) {
      const Real j = static_cast<Real>(k) * s;
      if (j < static_cast<Real>(lags)) sum += 2 * weight(j) * term(j);
    }
  } else if (lags <= kExactLags) {
    for (std::int64_t j = 1; j < lags; ++j) {
      sum += 2 * weight(static_cast<Real>(j)) * term(static_cast<Real>(j));
    }
  } else {
    // Many lags per cluster time: the sum as s times the integral over t = lag / s (trapezoid,
    // minus the end points' halves the sum does not have).
    const Real end = static_cast<Real>(lags) / s;
    constexpr int kSteps = 4000;
    const Real h = end / kSteps;
    Real integral = 0;
    for (int i = 0; i <= kSteps; ++i) {
      const Real t = h * i;
      const Real g = 2 * weight(t * s) * term(t * s);
      integral += (i == 0 || i == kSteps) ? g / 2 : g;
    }
    integral *= h;
    sum += s * integral - (2 * weight(0) * term(0) + 2 * weight(end * s) * term(end * s)) / 2;
  }
  if (!(sum > 0)) return 0.0;
  return static_cast<double>(z0 * z0 * big_m / sum);
}

int NoiseTypeOfSlope(double avar_slope) {
  if (!std::isfinite(avar_slope)) return 0;
  // Slope -2 is white or flicker phase; an IMU's is quantisation, white.
  if (avar_slope <= -1.5) return 2;
  return static_cast<int>(std::clamp(std::lround(-avar_slope - 1.0), -2L, 0L));
}

VarianceInterval ChiSquaredInterval(double variance, double edf, double confidence) {
  VarianceInterval v;
  if (!(edf > 0) || !(confidence > 0 && confidence < 1) || !std::isfinite(variance)) {
    v.low = 0.0;
    v.high = std::numeric_limits<double>::infinity();
    return v;
  }
  const boost::math::chi_squared chi2(edf);
  const double tail = (1.0 - confidence) / 2.0;
  v.low = variance * edf / boost::math::quantile(boost::math::complement(chi2, tail));
  v.high = variance * edf / boost::math::quantile(chi2, tail);
  return v;
}

}  // namespace turncal
