#pragma once
// The statistics the stillness detector and the noise meter (core/sequencing/stillness.cc,
// noise_meter.cc) share: robust sigma, float32's resolution, and the quantiles of their tests.

#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/fisher_f.hpp>
#include <boost/math/distributions/normal.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <cstddef>

namespace turncal::stillness_stats {

inline constexpr double kMadToSigma = 1.4826;  // sigma / MAD of a normal distribution
// A measured sigma below the float32 resolution of the value is the sensor's quantisation, not
// its noise; the floor keeps limits finite for a sensor that repeats the same value.
inline constexpr double kFloat32Resolution = 1.2e-7;
// One start-up attempt keeps at most this many samples (60 s at 10 kHz).
inline constexpr std::size_t kMaxMeterSamples = 600000;

// Two-sided normal (or Student's t with `dof`) quantile for a tail probability `alpha`.
inline double TwoSidedZ(double alpha, double dof) {
  if (std::isfinite(dof)) {
    return boost::math::quantile(boost::math::complement(boost::math::students_t(dof), alpha / 2));
  }
  return boost::math::quantile(boost::math::complement(boost::math::normal(), alpha / 2));
}

// Upper quantile of s^2 / sigma^2 for a variance from `n_dof` dof when sigma^2 came from `dof`.
inline double VarianceRatioLimit(double alpha, double n_dof, double dof) {
  if (std::isfinite(dof)) {
    return boost::math::quantile(boost::math::complement(boost::math::fisher_f(n_dof, dof), alpha));
  }
  return boost::math::quantile(boost::math::complement(boost::math::chi_squared(n_dof), alpha)) /
         n_dof;
}

// Values with lag-one correlation rho, taken as first-order autoregressive noise: n of them
// estimate a variance as n (1 - rho^2) / (1 + rho^2) independent ones would, and their mean
// varies (1 + rho) / (1 - rho) times more than independent values' (NoiseProfile::lag_one).
inline double Ar1DofShare(double rho) { return (1 - rho * rho) / (1 + rho * rho); }
inline double Ar1MeanInflation(double rho) { return (1 + rho) / (1 - rho); }

}  // namespace turncal::stillness_stats
