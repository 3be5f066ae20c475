// The warm-up transient's fit (core/analysis/warm_up.h) against simulated truth: the amplitude,
// the time constant and the warm-up time within their sigma over many recordings (the z-scores'
// mean and spread), no transient claimed where there is none, and the bins' memory bound.

#include "core/analysis/warm_up.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

namespace turncal {
namespace {

struct Truth {
  double settled = 0.01, amplitude = 0.004, tau_s = 60.0;
};

// 600 s at 100 Hz: the transient, white noise `white` per sample and a bias wander (a first-order
// Gauss-Markov process of `wander` and 20 s), binned into 1 s means.
WarmUpFit Simulate(const Truth& truth, double white, double wander, double threshold,
                   std::mt19937_64* rng) {
  std::normal_distribution<double> gauss;
  BinnedMeans bins(1.0);
  const double dt = 0.01, tau_w = 20.0;
  const double phi = std::exp(-dt / tau_w), drive = wander * std::sqrt(1 - phi * phi);
  double w = wander * gauss(*rng);
  for (int k = 0; k < 60000; ++k) {
    const double t = k * dt;
    w = phi * w + drive * gauss(*rng);
    const double v =
        truth.settled + truth.amplitude * std::exp(-t / truth.tau_s) + w + white * gauss(*rng);
    bins.Add(t, Eigen::Vector3d(v, 0, 0));
  }
  std::vector<double> t, y;
  bins.Series(0, &t, &y);
  // The noise model the fit is given: the truth's.
  BinNoiseModel noise;
  noise.white = white * std::sqrt(dt);
  if (wander > 0) noise.gauss_markov.push_back({tau_w, wander * wander});
  return FitWarmUp(t, y, 1.0, threshold, &noise);
}

struct Moments {
  double mean = 0, std = 0;
};
Moments Of(const std::vector<double>& z) {
  Moments m;
  for (double v : z) m.mean += v;
  m.mean /= static_cast<double>(z.size());
  for (double v : z) m.std += (v - m.mean) * (v - m.mean);
  m.std = std::sqrt(m.std / static_cast<double>(z.size()));
  return m;
}

void ExpectHonest(double white, double wander) {
  const Truth truth;
  const double threshold = 1e-4;
  const double time_truth = truth.tau_s * std::log(truth.amplitude / threshold);
  std::mt19937_64 rng(7);
  std::vector<double> z_amp, z_tau, z_time;
  constexpr int kRuns = 150;
  for (int run = 0; run < kRuns; ++run) {
    const WarmUpFit f = Simulate(truth, white, wander, threshold, &rng);
    ASSERT_TRUE(f.ok) << f.error;
    ASSERT_TRUE(f.resolved) << "run " << run;
    z_amp.push_back((f.amplitude - truth.amplitude) / f.amplitude_sigma);
    z_tau.push_back((f.tau_s - truth.tau_s) / f.tau_sigma);
    z_time.push_back((f.time_s - time_truth) / f.time_sigma);
  }
  // 150 runs: the mean's standard error is 0.08, the spread's about 0.06.
  for (const auto& [name, z] : {std::pair{"amplitude", z_amp}, {"tau", z_tau}, {"time", z_time}}) {
    const Moments m = Of(z);
    std::printf("%-9s z mean %+.3f std %.3f over %d runs\n", name, m.mean, m.std, kRuns);
    EXPECT_LT(std::fabs(m.mean), 0.3) << name;
    EXPECT_GT(m.std, 0.75) << name;
    EXPECT_LT(m.std, 1.3) << name;
  }
}

TEST(WarmUp, TheTransientAndItsTimeWithinTheirSigmaOnWhiteNoise) { ExpectHonest(2e-3, 0.0); }

// A bias that wanders (correlated from bin to bin) as well: the sigma are widened for it.
TEST(WarmUp, TheSigmaHoldWhenTheBiasWanders) { ExpectHonest(2e-3, 1.5e-4); }

TEST(WarmUp, NoTransientIsClaimedWhereThereIsNone) {
  Truth flat;
  flat.amplitude = 0.0;
  std::mt19937_64 rng(11);
  int claimed = 0;
  constexpr int kRuns = 100;
  for (int run = 0; run < kRuns; ++run) {
    const WarmUpFit f = Simulate(flat, 2e-3, 1e-4, 1e-4, &rng);
    ASSERT_TRUE(f.ok) << f.error;
    claimed += f.resolved;
  }
  // At 3 sigma a false transient is rare; the freedom in tau makes it likelier than 0.3 %.
  EXPECT_LE(claimed, 8);
}

TEST(WarmUp, BinsMergeWhenFullAndKeepTheMeans) {
  BinnedMeans bins(1.0, 16);
  for (int k = 0; k < 4000; ++k) bins.Add(k * 0.01, Eigen::Vector3d(k * 0.01, 1, 2));
  EXPECT_EQ(bins.bin_s(), 4.0);  // 40 s in at most 16 bins
  std::vector<double> t, y;
  bins.Series(0, &t, &y);
  ASSERT_EQ(t.size(), 9u);  // the last, partial, bin left out
  for (std::size_t i = 0; i < t.size(); ++i) EXPECT_NEAR(y[i], t[i] - 0.005, 1e-9);
}

TEST(WarmUp, TooShortIsAnError) {
  const WarmUpFit f = FitWarmUp({0.5, 1.5, 2.5}, {1, 1, 1}, 1.0, 1e-3);
  EXPECT_FALSE(f.ok);
  EXPECT_NE(f.error.find("8 bins"), std::string::npos);
}

}  // namespace
}  // namespace turncal
