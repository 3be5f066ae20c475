#pragma once
// Overlapping Allan deviation of one sensor axis and the noise model fitted to it (issue 19 item
// 1; IEEE Std 952 / 1293 practice, as allan_variance_ros and imu_utils give it): white noise of
// one-sided density N (the mean over T has variance N^2 / (2 T), turncal's convention), a
// first-order Gauss-Markov bias instability (sigma, tau) and a bias random walk (q: variance
// grows by q^2 per second). Their Allan variances add:
//   white     N^2 / (2 T)
//   GM        sigma^2 tau^2 / T^2 (2u - 3 + 4 e^-u - e^-2u),  u = T / tau
//   RW        q^2 T / 3
// The fit weighs each cluster time by how many independent clusters it has, and keeps every
// term non-negative. Pure computation.

#include <string>
#include <vector>

namespace turncal {

struct AllanPoint {
  double tau_s = 0.0;
  double adev = 0.0;      // Allan deviation, the series' unit
  double clusters = 0.0;  // independent clusters behind it (samples / m)
};

// Overlapping Allan deviation of samples spaced `dt_s` at about `per_decade` cluster sizes per
// decade from one sample up to a ninth of the series (fewer clusters are too noisy to use).
std::vector<AllanPoint> OverlappingAllan(const std::vector<double>& x, double dt_s,
                                         int per_decade = 10);

struct NoiseFit {
  bool ok = false;
  double white_density = 0.0;  // N, unit / sqrt(Hz)
  double gm_sigma = 0.0;       // Gauss-Markov stationary 1 sigma, unit
  double gm_tau_s = 0.0;       // its correlation time (0 when gm_sigma is 0)
  double random_walk = 0.0;    // q, unit / sqrt(s)
  // The flat bottom of the curve: min adev / 0.664 (IEEE "bias instability"), and where.
  double bias_instability = 0.0;
  double bias_instability_tau_s = 0.0;
  double rms_log_error = 0.0;  // of the fitted curve against the points, in ln(adev)
  // The longest cluster time in the data: a correlation time or random walk beyond a few times
  // this is an extrapolation (the report says so).
  double longest_tau_s = 0.0;

  // The model's Allan deviation at T.
  double Adev(double tau_s) const;
};

NoiseFit FitNoiseModel(const std::vector<AllanPoint>& points);

// Allan variance of each term at T (unit variance sigma^2 = q^2 = N^2 = 1).
double WhiteAvar(double tau_s);
double GaussMarkovAvar(double tau_s, double correlation_s);
double RandomWalkAvar(double tau_s);

}  // namespace turncal
