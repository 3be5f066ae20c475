#pragma once
// The IEEE Std 952-2020 noise terms of one axis and their sigma, from its overlapping Allan
// variance (issue 39 item 2). The standard's model (Annex C) adds five terms:
//   sigma^2(tau) = 3 Q^2 / tau^2        quantisation                    Q  unit*s (angle, velocity)
//                + N^2 / tau            angle / velocity random walk    N  unit/sqrt(Hz)
//                + (2 ln 2 / pi) B^2    bias instability (flicker)      B  unit
//                + K^2 tau / 3          rate random walk                K  unit/sqrt(s)
//                + R^2 tau^2 / 2        rate ramp                       R  unit/s
// N is the white rate's two-sided density: turncal's white density (the mean over T has variance
// N^2 / (2 T), allan.h) is sqrt(2) N; Kalibr's `noise_density` is N, its `random_walk` K.
//
// The variance is linear in (Q^2, N^2, B^2, K^2, R^2), so the fit is a least squares of the
// Allan variances -- generalised: the variances at neighbouring cluster times come from the same
// samples and are strongly correlated, and a fit that ignored it claims sigma up to twice too
// small (docs/ACCURACY.md "Noise terms"). Their covariance is computed from the model itself: each
// Allan difference is a second difference of the integrated rate, whose covariance for each noise
// type follows from its generalised autocovariance (allan_edf.h's, Greenhall & Riley): quantisation
// white phase, N white rate (-|t|), B flicker rate (t^2 ln|t|), K random-walk rate (|t|^3), the
// ramp a mean (cov(z1^2, z2^2) = 2 c^2 + 4 mu1 mu2 c for Gaussian differences of means mu). The fit
// iterates: weights from the current estimate, the non-negative generalised least squares over
// every subset of the terms, again; sigma from the Fisher information (A' C^-1 A)^-1 of the terms
// left free. A term the data cannot tell from zero is reported with its 95 % upper bound. Pure
// computation.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace turncal {

enum IeeeTerm { kIeeeQ = 0, kIeeeN = 1, kIeeeB = 2, kIeeeK = 3, kIeeeR = 4 };
inline constexpr int kIeeeTerms = 5;
const char* IeeeTermName(int term);  // "Q" ...

// The Allan variance of each term at tau for a coefficient of 1.
double IeeeUnitAvar(int term, double tau_s);

// A term's units for a triad ("acc" m/s^2, "gyr" rad/s, "mag" Gauss): the SI one the fit is in,
// and the datasheet's (deg/sqrt(h), deg/h, ug/sqrt(Hz) ...) with the factor from SI to it.
struct IeeeUnit {
  const char* si;
  const char* datasheet;
  double to_datasheet;
};
IeeeUnit IeeeTermUnit(const std::string& triad, int term);

struct IeeeAvarPoint {
  std::int64_t m = 0;  // cluster size in samples
  double avar = 0.0;   // measured overlapping Allan variance, unit^2
};

struct IeeeTermEstimate {
  double value = 0.0;  // the coefficient (the square root of the fitted variance term)
  double sigma = 0.0;  // its 1 sigma (delta method; 0 when value is 0)
  // The 95 % interval, from the variance term's +-1.96 sigma (clipped at zero).
  double low95 = 0.0, high95 = 0.0;
  // The variance term is at least 2 sigma from zero: otherwise only high95 means much.
  bool resolved = false;
};

struct IeeeNoiseFit {
  bool ok = false;
  std::string error;  // when not ok
  std::array<IeeeTermEstimate, kIeeeTerms> terms;
  double chi2 = 0.0;  // of the generalised residuals, with `dof` degrees of freedom
  int dof = 0;
  int points = 0;  // Allan variances fitted
  double tau_min_s = 0.0, tau_max_s = 0.0;

  // The fitted Allan deviation at tau.
  double Adev(double tau_s) const;
};

// Fits the five terms to `points` (cluster sizes from one sample up; use those with at least
// nine clusters, m <= n / 9) of a recording of n samples `dt_s` apart. Points closer than a
// factor 1.5 in m to the last kept are skipped (they add little and the covariance would be
// near singular).
// `independent`: the comparison a plain weighted fit makes, each variance's own scatter and no
// correlation between them (its sigma are too small; docs/ACCURACY.md "Noise terms").
IeeeNoiseFit FitIeeeNoise(const std::vector<IeeeAvarPoint>& points, double dt_s, std::int64_t n,
                          bool independent = false);

// IEEE's flicker B as a sum of first-order Gauss-Markov processes, three a decade with correlation
// times from `shortest_tau_s` to `longest_tau_s`, each of variance B^2 ln(10^(1/3)) / pi: their
// one-sided spectrum is B^2 / (pi f) between the ends, the Allan variance flat at B^2 2 ln 2 / pi
// within 3.5 % (the simulator's flicker, and the warm-up fit's model of the bias's wander).
struct GaussMarkovPole {
  double tau_s = 0.0, variance = 0.0;
};
std::vector<GaussMarkovPole> FlickerAsGaussMarkov(double b, double shortest_tau_s,
                                                  double longest_tau_s);

// The covariance of the overlapping Allan variances at cluster sizes m1 and m2 (samples) of n
// samples dt_s apart, for the terms' squared coefficients `theta` (Q^2, N^2, B^2, K^2, R^2).
// Exposed for its test against simulated scatter.
double AvarCovariance(std::int64_t m1, std::int64_t m2, double dt_s, std::int64_t n,
                      const std::array<double, kIeeeTerms>& theta);

}  // namespace turncal
