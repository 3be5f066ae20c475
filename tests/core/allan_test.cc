// Overlapping Allan deviation and the noise model fitted to it (core/analysis/allan.h).
#include "core/analysis/allan.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace turncal {
namespace {

// White noise of one-sided density N at rate f: per-sample sigma N sqrt(f / 2). The Allan
// deviation at m samples then scatters by about 1 / sqrt(2 (n / m)); the fit over 10 decades of
// points recovers N to a few percent.
TEST(Allan, WhiteNoiseDensityIsRecovered) {
  const double rate = 100, N = 2e-3;
  std::mt19937_64 rng(1);
  std::normal_distribution<double> normal;
  std::vector<double> x(200000);
  for (auto& v : x) v = 9.81 + N * std::sqrt(rate / 2) * normal(rng);
  const auto points = OverlappingAllan(x, 1.0 / rate);
  ASSERT_GT(points.size(), 30u);
  // Each point against N / sqrt(2 tau) while it has many clusters.
  for (const auto& p : points) {
    if (p.clusters < 1000) continue;
    EXPECT_NEAR(p.adev, N / std::sqrt(2 * p.tau_s), 4 * p.adev / std::sqrt(2 * p.clusters))
        << "tau " << p.tau_s;
  }
  const NoiseFit f = FitNoiseModel(points);
  ASSERT_TRUE(f.ok);
  EXPECT_NEAR(f.white_density, N, 0.03 * N);
  // The drift terms it finds are negligible against the white noise over the data's span.
  EXPECT_LT(f.Adev(f.longest_tau_s), 1.3 * N / std::sqrt(2 * f.longest_tau_s));
  EXPECT_LT(f.rms_log_error, 0.1);
}

// White noise plus a Gauss-Markov bias (sigma 5 N-over-a-second, tau 20 s) over 4000 s: the fit
// finds both; sigma within 30 % and tau within a factor of 2 (the curve's bump is broad).
TEST(Allan, GaussMarkovBiasIsRecovered) {
  const double rate = 50, N = 1e-3, sigma = 2e-3, tau = 20;
  std::mt19937_64 rng(2);
  std::normal_distribution<double> normal;
  const double dt = 1 / rate, phi = std::exp(-dt / tau), drive = sigma * std::sqrt(1 - phi * phi);
  double b = sigma * normal(rng);
  std::vector<double> x(200000);
  for (auto& v : x) {
    b = phi * b + drive * normal(rng);
    v = b + N * std::sqrt(rate / 2) * normal(rng);
  }
  const NoiseFit f = FitNoiseModel(OverlappingAllan(x, dt));
  ASSERT_TRUE(f.ok);
  EXPECT_NEAR(f.white_density, N, 0.05 * N);
  EXPECT_NEAR(f.gm_sigma, sigma, 0.3 * sigma);
  EXPECT_GT(f.gm_tau_s, tau / 2);
  EXPECT_LT(f.gm_tau_s, tau * 2);
  // The fitted curve follows the points (ln error), and the IEEE flat-bottom figure is the
  // curve's minimum over the data / 0.664.
  EXPECT_LT(f.rms_log_error, 0.1);
  EXPECT_GT(f.bias_instability, 0.0);
}

TEST(Allan, RandomWalkIsRecovered) {
  const double rate = 20, N = 1e-3, q = 2e-4;
  std::mt19937_64 rng(3);
  std::normal_distribution<double> normal;
  double b = 0;
  std::vector<double> x(100000);
  for (auto& v : x) {
    b += q * std::sqrt(1 / rate) * normal(rng);
    v = b + N * std::sqrt(rate / 2) * normal(rng);
  }
  const NoiseFit f = FitNoiseModel(OverlappingAllan(x, 1 / rate));
  ASSERT_TRUE(f.ok);
  // A random walk and a Gauss-Markov process with tau far beyond the data look alike (q^2 =
  // 2 sigma^2 / tau); either way the model's Allan deviation at the longest tau is right.
  const double T = f.longest_tau_s;
  const double expected = std::sqrt(N * N / (2 * T) + q * q * T / 3);
  EXPECT_NEAR(f.Adev(T), expected, 0.3 * expected);
  EXPECT_NEAR(f.white_density, N, 0.05 * N);
}

TEST(Allan, TheTermsMatchTheirClosedForms) {
  // GM at T << tau is a random walk of q^2 = 2 / tau; at T >> tau white of N^2 = 4 tau
  // (sigma_A^2 -> 2 tau / T).
  EXPECT_NEAR(GaussMarkovAvar(1e-4, 100), 2.0 / 100 * RandomWalkAvar(1e-4), 1e-10);
  EXPECT_NEAR(GaussMarkovAvar(1e6, 100), 4 * 100 * WhiteAvar(1e6), 1e-7);
  EXPECT_TRUE(OverlappingAllan({1, 2, 3}, 0.01).empty());
  EXPECT_FALSE(FitNoiseModel({}).ok);
}

}  // namespace
}  // namespace turncal
