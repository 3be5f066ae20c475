// The noise of values in motion correlated from one to the next
// (core/estimation/free_correlation.h; issue 37): its lag-one correlation and time constant
// measured from residuals at irregular instants, white noise left as it is, and the chain's
// whitening exact (W S W^T = I).

#include "core/estimation/free_correlation.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

namespace turncal {
namespace {

// n values of an exponentially correlated unit-variance noise (time constant tau_s; 0: white) at
// instants 10 ms apart, every 7th 20 ms apart (a mixed spacing, as a station's decimation makes).
std::vector<MotionResidual> Noise(int n, double tau_s, std::uint32_t seed) {
  std::mt19937 random(seed);
  std::normal_distribution<double> normal;
  std::vector<MotionResidual> out;
  double t = 0, r = normal(random);
  for (int k = 0; k < n; ++k) {
    if (k > 0) {
      const double dt = k % 7 == 0 ? 0.02 : 0.01;
      t += dt;
      const double phi = tau_s > 0 ? std::exp(-dt / tau_s) : 0.0;
      r = phi * r + std::sqrt(1 - phi * phi) * normal(random);
    }
    out.push_back({t, r});
  }
  return out;
}

TEST(MotionCorrelation, ATimeConstantIsMeasuredAtMixedSpacing) {
  const double tau = 0.016;  // a 10-Hz first-order filter's
  double sum_tau_s = 0;
  for (std::uint32_t seed = 1; seed <= 100; ++seed) {
    const MotionCorrelation c = MeasureMotionCorrelation(Noise(1000, tau, seed));
    EXPECT_GE(c.pairs, 990);  // 999, less any beyond 4 robust sigmas
    EXPECT_NEAR(c.spacing_s, 0.01, 1e-9);
    ASSERT_TRUE(c.correlated()) << c.lag_one;
    // The lag-one correlation's sigma is about sqrt((1 - rho^2) / n) = 0.027 at rho 0.5 (0.028
    // over 400 seeds); tau's relative sigma that over rho |ln rho|, 0.09: 4 sigma.
    EXPECT_NEAR(c.tau_s, tau, 0.36 * tau) << "seed " << seed;
    sum_tau_s += c.tau_s;
    EXPECT_NEAR(c.at_spacing(), std::exp(-c.spacing_s / c.tau_s), 1e-15);
  }
  // Unbiased: the mean of 100 within 3 of its sigmas (0.009 tau; 400 seeds gave 0.99 tau).
  EXPECT_NEAR(sum_tau_s / 100, tau, 0.027 * tau);
}

// Residuals at a fit: the noise less its least-squares fit on p columns smooth over the
// correlation time (a hand's rotation seen by 10-ms values: slow sines and cosines).
std::vector<MotionResidual> ResidualsAtAFit(int n, double tau_s, int p, std::uint32_t seed) {
  std::vector<MotionResidual> noise = Noise(n, tau_s, seed);
  Eigen::MatrixXd J(n, p);
  Eigen::VectorXd y(n);
  for (int k = 0; k < n; ++k) {
    const double t = noise[static_cast<std::size_t>(k)].t_s;
    for (int j = 0; j < p; ++j) {
      const double phase = 0.7 * ((j + 1) / 2) * t + 0.3 * j;
      J(k, j) = j == 0 ? 1.0 : j % 2 ? std::sin(phase) : std::cos(phase);
    }
    y[k] = noise[static_cast<std::size_t>(k)].r;
  }
  const Eigen::VectorXd r = y - J * J.colPivHouseholderQr().solve(y);
  for (int k = 0; k < n; ++k) noise[static_cast<std::size_t>(k)].r = r[k];
  return noise;
}

// The fit's projection takes part of the correlation out: at rho 0.53 over 600 values and 9
// parameters the raw lag-one is 0.02 low on average (the free row's sigma 2.5 % small), and the
// corrected one is not.
TEST(MotionCorrelation, TheFitsProjectionIsAllowedFor) {
  const double tau = 1.0 / (2 * M_PI * 10.0);
  double raw = 0, corrected = 0, expected = 0;
  const int seeds = 300;
  for (std::uint32_t seed = 1; seed <= seeds; ++seed) {
    const std::vector<MotionResidual> r = ResidualsAtAFit(600, tau, 9, seed);
    const MotionCorrelation c = MeasureMotionCorrelation(r, 0.1, 3.5, 9);
    raw += c.lag_one_raw;
    corrected += c.lag_one;
    // The mean exp(-dt / tau) over the pairs: the correlation the noise has.
    double sum = 0;
    for (std::size_t k = 1; k < r.size(); ++k) sum += std::exp(-(r[k].t_s - r[k - 1].t_s) / tau);
    expected += sum / static_cast<double>(r.size() - 1);
  }
  raw /= seeds;
  corrected /= seeds;
  expected /= seeds;
  std::printf(
      "lag-one over %d fits of 9 parameters to 600 values: raw %.4f, corrected %.4f, the "
      "noise's %.4f\n",
      seeds, raw, corrected, expected);
  // The mean over 300 seeds has the sigma 0.032 / sqrt(300) = 0.0019.
  EXPECT_LT(raw, expected - 0.012) << raw << " " << expected;
  EXPECT_NEAR(corrected, expected, 3 * 0.0019) << corrected << " " << expected;
}

TEST(MotionCorrelation, WhiteNoiseIsNotTakenAsCorrelated) {
  int flagged = 0;
  for (std::uint32_t seed = 1; seed <= 200; ++seed) {
    const MotionCorrelation c = MeasureMotionCorrelation(Noise(1000, 0.0, seed));
    EXPECT_NEAR(c.threshold, std::max(0.1, 3.5 / std::sqrt(static_cast<double>(c.pairs))), 1e-12);
    flagged += c.correlated();
  }
  // 3.5 sigma of the lag-one correlation (and at least 0.1): P about 2e-4 per capture.
  EXPECT_LE(flagged, 1);
}

TEST(MotionCorrelation, TooFewPairsMeasureNothingAndAPauseBreaksThePairs) {
  EXPECT_EQ(MeasureMotionCorrelation(Noise(15, 0.016, 1)).pairs, 0);
  // A pause of 10 s in the middle: the pair across it is not one (more than 3 spacings apart).
  std::vector<MotionResidual> paused = Noise(100, 0.016, 2);
  for (std::size_t k = 50; k < paused.size(); ++k) paused[k].t_s += 10.0;
  const MotionCorrelation c = MeasureMotionCorrelation(paused);
  EXPECT_EQ(c.pairs, 98);
  EXPECT_TRUE(c.correlated()) << c.lag_one;
}

TEST(MotionCorrelation, ADisturbanceIsNotReadAsCorrelation) {
  // White noise with a smooth bump of 40 sigma over 50 values (a magnet passing by): its values
  // beyond 4 robust sigmas are left out of the pairs.
  std::vector<MotionResidual> r = Noise(1000, 0.0, 3);
  for (int k = 400; k < 450; ++k) {
    r[static_cast<std::size_t>(k)].r += 20.0 * (1 - std::cos(2 * M_PI * (k - 400) / 50.0));
  }
  const MotionCorrelation c = MeasureMotionCorrelation(r);
  EXPECT_FALSE(c.correlated()) << c.lag_one;
  EXPECT_LT(c.pairs, 999);
}

TEST(MotionCorrelation, TheChainsWhiteningIsExact) {
  // Six residuals: rows 0 and 4 independent, rows 1, 2, 3, 5 a chain out of time order.
  CorrelatedChain chain;
  chain.rows = {1, 5, 2, 3};
  chain.t_s = {0.00, 0.05, 0.01, 0.03};
  chain.tau_s = 0.02;
  Eigen::MatrixXd S = Eigen::MatrixXd::Identity(6, 6);
  AddChainCovariance(chain, &S);
  EXPECT_NEAR(S(1, 2), std::exp(-0.5), 1e-15);
  EXPECT_NEAR(S(5, 1), std::exp(-2.5), 1e-15);
  EXPECT_EQ(S(0, 1), 0.0);
  const Eigen::MatrixXd W = ChainWhitener(6, chain);
  EXPECT_TRUE((W * S * W.transpose()).isIdentity(1e-12)) << W * S * W.transpose();
  // chi^2's share of degrees of freedom: 6 / (6 + 2 sum_{i<j} rho_ij^2), rho_ij^2 = exp(-2 dt /
  // tau) over the chain's six pairs (0.01, 0.02, 0.02, 0.03, 0.04, 0.05 s apart).
  const double sum =
      std::exp(-1.0) + 2 * std::exp(-2.0) + std::exp(-3.0) + std::exp(-4.0) + std::exp(-5.0);
  EXPECT_NEAR(ChainChi2DofShare(chain, 6), 6 / (6 + 2 * sum), 1e-15);
  // No time constant: nothing correlated.
  chain.tau_s = 0;
  EXPECT_TRUE(ChainWhitener(6, chain).isIdentity(0.0));
  EXPECT_EQ(ChainChi2DofShare(chain, 6), 1.0);
}

// Whitened with a time constant measured from the same values, chi^2 varies as their plain sum of
// squares does, more than chi^2_m: its variance is 2 m / share (ChainChi2DofShare), and the fit
// check's p-values are uniform only with that share (without it, the free row's fit check
// refused 18 % of runs at the lowest tenth where 10 % were due).
TEST(MotionCorrelation, AMeasuredCorrelationLeavesTheChiSquareFewerDegreesOfFreedom) {
  const double tau = 1.0 / (2 * M_PI * 10.0);
  const int m = 600, seeds = 1000;
  double sum = 0, sum2 = 0, share = 0;
  for (std::uint32_t seed = 1; seed <= seeds; ++seed) {
    const std::vector<MotionResidual> r = Noise(m, tau, 5000 + seed);
    const MotionCorrelation c = MeasureMotionCorrelation(r);
    ASSERT_TRUE(c.correlated());
    CorrelatedChain chain;
    chain.tau_s = c.tau_s;
    for (int k = 0; k < m; ++k) {
      chain.rows.push_back(k);
      chain.t_s.push_back(r[static_cast<std::size_t>(k)].t_s);
    }
    double chi2 = r[0].r * r[0].r;  // Prais-Winsten, as ChainWhitener's rows
    for (std::size_t k = 1; k < r.size(); ++k) {
      const double phi = std::exp(-(r[k].t_s - r[k - 1].t_s) / c.tau_s);
      const double e = (r[k].r - phi * r[k - 1].r) / std::sqrt(1 - phi * phi);
      chi2 += e * e;
    }
    sum += chi2;
    sum2 += chi2 * chi2;
    share += ChainChi2DofShare(chain, m);
  }
  const double mean = sum / seeds, variance = sum2 / seeds - mean * mean;
  share /= seeds;
  std::printf(
      "chi^2 of %d values whitened with their own tau over %d seeds: mean %.1f, variance %.0f "
      "(chi^2_m: %d; 2 m / share: %.0f, share %.3f)\n",
      m, seeds, mean, variance, 2 * m, 2 * m / share, share);
  // The variance's relative sigma over 1000 seeds is sqrt(2 / 1000) = 0.045: 4 sigma.
  EXPECT_NEAR(variance / (2 * m / share), 1.0, 0.18);
  EXPECT_GT(variance / (2 * m), 1.0 + 0.18);
  EXPECT_NEAR(mean, m, 4 * std::sqrt(2 * m / share / seeds));
}

}  // namespace
}  // namespace turncal
