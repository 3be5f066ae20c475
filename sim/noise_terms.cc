#include "sim/noise_terms.h"

#include <algorithm>
#include <cmath>

namespace turncal::sim {

std::vector<FlickerPole> FlickerPoles(double b, double dt_s, double span_s) {
  return FlickerAsGaussMarkov(b, dt_s / 30.0, 100.0 * span_s);
}

NoiseTermsGenerator::NoiseTermsGenerator(const NoiseTerms& terms, double dt_s, double span_s,
                                         std::uint64_t seed)
    : terms_(terms), dt_s_(dt_s), rng_(seed) {
  bias_ = terms_.turn_on_bias * gauss_(rng_);
  angle_error_ = terms_.q * std::sqrt(12.0) * uniform_(rng_);
  // Each Gauss-Markov process (Ornstein-Uhlenbeck, beta = 1 / tau, stationary variance s^2) is
  // averaged over the sample interval, as a sensor's output is: given x at the interval's start,
  // x at its end and the integral I over it are jointly Gaussian with
  //   var x = s^2 (1 - phi^2),  var I = s^2 / beta^2 (2 beta dt - 3 + 4 phi - phi^2),
  //   cov = s^2 / beta (1 - phi)^2,  means phi x and x (1 - phi) / beta  (phi = e^-beta dt),
  // drawn through the 2x2 Cholesky factor. Its Allan variance is then exactly the continuous
  // one, GaussMarkovAvar.
  for (const FlickerPole& pole : FlickerPoles(terms_.b, dt_s, span_s)) {
    Pole p;
    const double beta = 1.0 / pole.tau_s, s2 = pole.variance;
    const double x = beta * dt_s;
    p.phi = std::exp(-x);
    const double one_minus_phi = -std::expm1(-x);
    p.mean_integral = one_minus_phi / beta;
    const double var_x = -s2 * std::expm1(-2.0 * x);
    // 2x - 3 + 4 e^-x - e^-2x loses every digit for a correlation time far beyond the sample
    // period: its series, 2x^3/3 - x^4/2 + 7x^5/30, there.
    const double bracket = x < 1e-2 ? x * x * x * (2.0 / 3.0 - x / 2.0 + 7.0 * x * x / 30.0)
                                    : 2.0 * x - 3.0 + 4.0 * p.phi - p.phi * p.phi;
    const double var_i = std::max(0.0, s2 / (beta * beta) * bracket);
    const double cov = s2 / beta * one_minus_phi * one_minus_phi;
    p.l11 = std::sqrt(var_x);
    p.l21 = p.l11 > 0 ? cov / p.l11 : 0.0;
    p.l22 = std::sqrt(std::max(0.0, var_i - p.l21 * p.l21));
    p.x = std::sqrt(s2) * gauss_(rng_);
    poles_.push_back(p);
  }
}

double NoiseTermsGenerator::Next() {
  double flicker_integral = 0.0;
  for (Pole& p : poles_) {
    const double u1 = gauss_(rng_), u2 = gauss_(rng_);
    flicker_integral += p.mean_integral * p.x + p.l21 * u1 + p.l22 * u2;
    p.x = p.phi * p.x + p.l11 * u1;
  }
  const double flicker = flicker_integral / dt_s_;
  const double white = terms_.n / std::sqrt(dt_s_) * gauss_(rng_);
  const double next_angle_error = terms_.q * std::sqrt(12.0) * uniform_(rng_);
  const double quantisation = (next_angle_error - angle_error_) / dt_s_;
  angle_error_ = next_angle_error;
  const double value = bias_ + walk_ + terms_.r * t_s_ + flicker + white + quantisation;
  walk_ += terms_.k * std::sqrt(dt_s_) * gauss_(rng_);
  t_s_ += dt_s_;
  return value;
}

}  // namespace turncal::sim
