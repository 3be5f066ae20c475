// The Kolmogorov-Smirnov test against uniform (montecarlo/ks_uniform.h): its statistic on
// samples whose D is known by construction, its p-value against tabulated points of the
// Kolmogorov distribution, and its behaviour on uniform and shifted random samples.
#include "montecarlo/ks_uniform.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace turncal::montecarlo {
namespace {

// n points spaced evenly over [shift, 1]: p_i = shift + (1 - shift) (i - 1/2) / n. The empirical
// distribution is furthest below the uniform's just before p_1 (by p_1) and above it just after
// p_n (by 1 - p_n), so D = max(shift + (1 - shift) / 2n, (1 - shift) / 2n) = shift + (1 - shift)
// / 2n.
std::vector<double> ShiftedGrid(int n, double shift) {
  std::vector<double> p;
  for (int i = 1; i <= n; ++i) p.push_back(shift + (1 - shift) * (i - 0.5) / n);
  return p;
}

// The shift that gives the grid of n points Stephens' lambda = (sqrt(n) + 0.12 + 0.11 /
// sqrt(n)) D equal to `lambda`.
double ShiftFor(int n, double lambda) {
  const double d = lambda / (std::sqrt(n) + 0.12 + 0.11 / std::sqrt(n));
  return (d - 0.5 / n) / (1 - 0.5 / n);
}

TEST(KsUniform, TheStatisticOfAnEvenGridIsHalfAStep) {
  // p_i = (i - 1/2) / n: the empirical distribution is 1/2n from the uniform's on each side.
  for (int n : {1, 2, 10, 1000}) {
    EXPECT_NEAR(KsUniform(ShiftedGrid(n, 0.0)).d, 0.5 / n, 1e-15) << n;
  }
  EXPECT_NEAR(KsUniform(ShiftedGrid(50, 0.2)).d, 0.2 + 0.8 / 100, 1e-15);
  // One value: D = max(1 - p, p).
  EXPECT_DOUBLE_EQ(KsUniform({0.3}).d, 0.7);
  EXPECT_DOUBLE_EQ(KsUniform({0.9}).d, 0.9);
}

TEST(KsUniform, TheOrderOfTheSampleDoesNotMatter) {
  std::vector<double> p = ShiftedGrid(20, 0.1);
  const KsTest sorted = KsUniform(p);
  std::reverse(p.begin(), p.end());
  EXPECT_EQ(KsUniform(p).d, sorted.d);
  EXPECT_EQ(KsUniform(p).p, sorted.p);
}

// Q_KS(lambda) at the Kolmogorov distribution's tabulated quantiles (Smirnov 1948; the
// critical values 1.2238, 1.3581, 1.6276, 1.9495 of the 10 %, 5 %, 1 % and 0.1 % levels, the
// median 0.8276 and Q(1) = 0.2700), reached through samples of 100 points whose D gives that
// lambda. The tables' lambda carry four decimals, which moves Q by less than 1e-4 of itself.
TEST(KsUniform, ThePValueIsTheKolmogorovDistributionsTail) {
  const std::vector<std::pair<double, double>> table = {
      {0.8276, 0.5}, {1.0, 0.27}, {1.2238, 0.10}, {1.3581, 0.05}, {1.6276, 0.01}, {1.9495, 0.001}};
  for (const auto& [lambda, q] : table) {
    const int n = 100;
    const KsTest t = KsUniform(ShiftedGrid(n, ShiftFor(n, lambda)));
    EXPECT_NEAR(t.p / q, 1.0, 1e-3) << "lambda " << lambda << ", p " << t.p;
  }
}

// Q_KS sums 100 terms of its alternating series, exact (to rounding) for lambda >= 0.05, where
// the first term left out, 2 exp(-2 101^2 lambda^2), is below 1e-21: 100 evenly spread points
// (lambda 0.0507) give p = 1 to rounding. Below that the sum falls short of 1 (lambda 0.016:
// 0.994), which no criterion (p > 0.01) notices.
TEST(KsUniform, PerfectAgreementGivesAPValueOfOne) {
  EXPECT_NEAR(KsUniform(ShiftedGrid(100, 0.0)).p, 1.0, 1e-12);
  EXPECT_NEAR(KsUniform(ShiftedGrid(1000, 0.0)).p, 1.0, 0.01);
}

// Uniform samples are rejected at the 5 % level about 5 % of the time: 400 samples of 50, the
// count of p < 0.05 is binomial(400, 0.05), 20 +- 4.4; within 4 sigma of it. (Stephens'
// correction makes the asymptotic p-value good to n of about 5.)
TEST(KsUniform, UniformSamplesAreRejectedAtTheirLevel) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int rejected = 0;
  for (int s = 0; s < 400; ++s) {
    std::vector<double> p(50);
    for (double& v : p) v = u(rng);
    rejected += KsUniform(p).p < 0.05;
  }
  EXPECT_GE(rejected, 20 - 18);
  EXPECT_LE(rejected, 20 + 18);
}

// Uniform on [0.2, 1] instead of [0, 1]: D is near 0.2, lambda near 0.2 sqrt(200) = 2.8, and
// Q(2.8) = 2 exp(-15.7) ~ 3e-7.
TEST(KsUniform, AShiftedSampleIsRejected) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0.2, 1.0);
  std::vector<double> p(200);
  for (double& v : p) v = u(rng);
  const KsTest t = KsUniform(p);
  EXPECT_NEAR(t.d, 0.2, 0.1);
  EXPECT_LT(t.p, 1e-4);
}

}  // namespace
}  // namespace turncal::montecarlo
