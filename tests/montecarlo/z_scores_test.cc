// The z-score summary of the Monte Carlo engines (montecarlo/z_scores.h): mean, spread and
// counts beyond 3 and 4 sigma on inputs whose answers are known, and on a normal sample.
#include "montecarlo/z_scores.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace turncal::montecarlo {
namespace {

ZScoreSummary Summary(const std::vector<std::vector<double>>& runs) {
  ZScoreSummary s(static_cast<int>(runs.front().size()));
  for (const auto& r : runs) s.Add(Eigen::Map<const Eigen::VectorXd>(r.data(), r.size()));
  return s;
}

// Two parameters over four runs: z0 = +-1 (mean 0, spread 1) and z1 = 3.5, 0, 0, 4.5 (mean 2,
// mean square 32.5 / 4 = 8.125, spread sqrt(8.125 - 4)).
TEST(ZScoreSummary, MeanSpreadAndCountsOfKnownScores) {
  const ZScoreSummary s = Summary({{1, 3.5}, {-1, 0}, {1, 0}, {-1, 4.5}});
  EXPECT_EQ(s.runs(), 4);
  EXPECT_EQ(s.parameters(), 2);
  EXPECT_DOUBLE_EQ(s.Mean()[0], 0.0);
  EXPECT_DOUBLE_EQ(s.Mean()[1], 2.0);
  EXPECT_DOUBLE_EQ(s.Std()[0], 1.0);
  EXPECT_DOUBLE_EQ(s.Std()[1], std::sqrt(4.125));
  EXPECT_EQ(s.BeyondThree()[0], 0);
  EXPECT_EQ(s.BeyondThree()[1], 2);
  EXPECT_EQ(s.BeyondFour()[1], 1);
  EXPECT_TRUE(s.Honest(0));
  EXPECT_FALSE(s.Honest(1));
}

// The counts are strictly beyond: |z| = 3 and |z| = 4 count for neither.
TEST(ZScoreSummary, CountsAreStrictlyBeyondAndBothSigns) {
  const ZScoreSummary s = Summary({{3.0}, {-3.0}, {4.0}, {-3.01}, {-4.01}, {4.5}});
  EXPECT_EQ(s.BeyondThree()[0], 4);
  EXPECT_EQ(s.BeyondFour()[0], 2);
}

// The verdict's edges (docs/ACCURACY.md): spread in [0.9, 1.1] and |mean| <= 0.15. Scores
// m +- a have mean m and spread a exactly.
TEST(ZScoreSummary, TheVerdictHoldsInsideItsBoundsOnly) {
  auto honest = [](double mean, double spread) {
    return Summary({{mean + spread}, {mean - spread}}).Honest(0);
  };
  EXPECT_TRUE(honest(0.0, 1.0));
  EXPECT_TRUE(honest(0.14, 0.91));
  EXPECT_TRUE(honest(-0.14, 1.09));
  EXPECT_FALSE(honest(0.16, 1.0));
  EXPECT_FALSE(honest(-0.16, 1.0));
  EXPECT_FALSE(honest(0.0, 0.85));
  EXPECT_FALSE(honest(0.0, 1.15));
}

// Constant scores: mean z^2 - mean^2 is 0 give or take an ulp, which must not make the spread
// NaN (the square root of -1 ulp) nor more than the root of a few ulps.
TEST(ZScoreSummary, ConstantScoresHaveNoSpread) {
  for (double z : {0.1, 0.7, -2.3, 1e3}) {
    const ZScoreSummary s = Summary({{z}, {z}, {z}});
    EXPECT_NEAR(s.Mean()[0], z, 1e-15 * std::abs(z));
    EXPECT_FALSE(std::isnan(s.Std()[0]));
    EXPECT_LT(s.Std()[0], 1e-7 * std::abs(z));
  }
}

TEST(ZScoreSummary, NoRunGivesNoMeanAndNoSpread) {
  const ZScoreSummary s(3);
  EXPECT_EQ(s.runs(), 0);
  EXPECT_TRUE(std::isnan(s.Mean()[0]));
  EXPECT_EQ(s.Std()[0], 0.0);
  EXPECT_EQ(s.BeyondThree().sum(), 0);
}

// 20000 standard normal scores per parameter: the mean within 4 / sqrt(n) = 0.028 of 0, the
// spread within 4 / sqrt(2 n) = 0.02 of 1, beyond 3 sigma n 0.27 % = 54 (Poisson, +- 4 sqrt(54)
// = 29), beyond 4 sigma n 0.0063 % = 1.3 (at most 8: P < 1e-4). A scale of 2 on the second
// parameter doubles its spread and leaves it dishonest.
TEST(ZScoreSummary, NormalScoresHaveUnitSpreadAndTheirTails) {
  const int n = 20000;
  std::mt19937_64 rng(3);
  std::normal_distribution<double> normal;
  ZScoreSummary s(2);
  for (int i = 0; i < n; ++i) {
    const double z = normal(rng);
    s.Add(Eigen::Vector2d(z, 2 * normal(rng)));
  }
  EXPECT_NEAR(s.Mean()[0], 0.0, 4 / std::sqrt(n));
  EXPECT_NEAR(s.Std()[0], 1.0, 4 / std::sqrt(2.0 * n));
  EXPECT_NEAR(s.BeyondThree()[0], n * 0.0027, 4 * std::sqrt(n * 0.0027));
  EXPECT_LE(s.BeyondFour()[0], 8);
  EXPECT_TRUE(s.Honest(0));
  EXPECT_NEAR(s.Std()[1], 2.0, 8 / std::sqrt(2.0 * n));
  EXPECT_FALSE(s.Honest(1));
}

// z2 = 0.6 z0 + 0.8 e over 20000 runs: correlation 0.6 within 4 (1 - 0.36) / sqrt(n) = 0.018,
// z0 and z1 independent within 4 / sqrt(n) = 0.028; a parameter with no spread is uncorrelated
// (the identity's entries), and so is everything with fewer than two runs.
TEST(ZScoreSummary, TheCorrelationOfTheParametersScores) {
  const int n = 20000;
  std::mt19937_64 rng(5);
  std::normal_distribution<double> normal;
  ZScoreSummary s(4);
  for (int i = 0; i < n; ++i) {
    const double z0 = normal(rng), z1 = normal(rng);
    s.Add(Eigen::Vector4d(z0, z1, 0.6 * z0 + 0.8 * normal(rng), 1.5));
  }
  const Eigen::MatrixXd c = s.Correlation();
  EXPECT_NEAR(c(2, 0), 0.6, 4 * 0.64 / std::sqrt(n));
  EXPECT_DOUBLE_EQ(c(0, 2), c(2, 0));
  EXPECT_NEAR(c(1, 0), 0.0, 4 / std::sqrt(n));
  EXPECT_DOUBLE_EQ(c(3, 0), 0.0);
  for (int i = 0; i < 4; ++i) EXPECT_DOUBLE_EQ(c(i, i), 1.0);
  ZScoreSummary one(2);
  one.Add(Eigen::Vector2d(1, 2));
  EXPECT_TRUE(one.Correlation().isIdentity());
}

// An honest sigma's rows against the verdict. Normal z's mean and spread are independent, so a
// parameter passes with P(|mean| <= 0.15) P(0.81 n <= chi^2_(n-1) <= 1.21 n): 0.96611 x 0.95423
// = 0.92189 at n = 200 (0.99923 at 600), and nine independent ones with its ninth power,
// 0.48095 (0.99313 at 600). Nine z that are one (correlation 1) pass as one. The simulated
// chance within 4 binomial sigma: sqrt(p (1 - p) / rows).
TEST(HonestRowPassChance, IsTheVerdictsFalseAlarmRateForIndependentAndCorrelatedScores) {
  const auto tolerance = [](double p, int rows) { return 4 * std::sqrt(p * (1 - p) / rows); };
  const Eigen::MatrixXd nine = Eigen::MatrixXd::Identity(9, 9);
  EXPECT_NEAR(HonestRowPassChance(nine, 200, 4000), 0.48095, tolerance(0.48095, 4000));
  EXPECT_NEAR(HonestRowPassChance(nine, 600, 1000), 0.99313, tolerance(0.99313, 1000));
  EXPECT_NEAR(HonestRowPassChance(Eigen::MatrixXd::Identity(1, 1), 200, 4000), 0.92189,
              tolerance(0.92189, 4000));
  EXPECT_NEAR(HonestRowPassChance(Eigen::MatrixXd::Ones(9, 9), 200, 4000), 0.92189,
              tolerance(0.92189, 4000));
  EXPECT_TRUE(std::isnan(HonestRowPassChance(nine, 1)));
}

}  // namespace
}  // namespace turncal::montecarlo
