// A parameter's drift over a unit's calibrations (core/analysis/parameter_drift.h) against
// simulated units with a known trend, turn-on scatter and calibration sigma: 12 calibrations
// over a year, two of them on the same day as another.

#include "core/analysis/parameter_drift.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

namespace turncal {
namespace {

struct Truth {
  double value = 0.05, slope_per_month = 3e-5;  // e.g. an accelerometer bias, m/s^2
  double calibration_sigma = 2e-5, turn_on = 3e-5;
  double tolerance = 1e-4;
};

// Months 0..7 one calibration each; months 9 and 11 two each, hours apart (switched off and on
// between): 12 calibrations over a year.
std::vector<DriftPoint> Unit(const Truth& truth, std::mt19937_64* rng) {
  std::normal_distribution<double> gauss;
  const double t0 = 1767225600.0;  // 2026-01-01
  std::vector<double> times;
  for (int month = 0; month < 8; ++month)
    times.push_back(t0 + month * kSecondsPerMonth + 3600 * 10);
  for (int month : {9, 11}) {
    times.push_back(t0 + month * kSecondsPerMonth + 3600 * 9);
    times.push_back(t0 + month * kSecondsPerMonth + 3600 * 15);
  }
  std::vector<DriftPoint> points;
  for (double t : times) {
    const double value = truth.value + truth.slope_per_month * (t - t0) / kSecondsPerMonth +
                         truth.turn_on * gauss(*rng) + truth.calibration_sigma * gauss(*rng);
    points.push_back({t, value, truth.calibration_sigma});
  }
  return points;
}

TEST(ParameterDrift, TheTrendTheRepeatabilityAndTheRecalibrationDateAreHonest) {
  const Truth truth;
  std::mt19937_64 rng(39);
  constexpr int kUnits = 400;
  std::vector<double> z_slope, z_date;
  int repeat_covered = 0, resolved = 0;
  const double repeat_truth = std::hypot(truth.turn_on, truth.calibration_sigma);
  for (int u = 0; u < kUnits; ++u) {
    const std::vector<DriftPoint> points = Unit(truth, &rng);
    const ParameterDrift d = AnalyseParameterDrift(points, truth.tolerance);
    ASSERT_TRUE(d.ok) << d.error;
    ASSERT_EQ(d.calibrations, 12);
    ASSERT_EQ(d.repeat_groups, 2);
    ASSERT_EQ(d.repeat_dof, 2);
    const double slope = truth.slope_per_month / kSecondsPerMonth;
    z_slope.push_back((d.slope_per_s - slope) / d.slope_sigma_per_s);
    repeat_covered +=
        d.repeatability_low95 <= repeat_truth && repeat_truth <= d.repeatability_high95;
    if (d.has_recalibration) {
      ++resolved;
      const double date = d.last_t_s + truth.tolerance / slope;
      z_date.push_back((d.recalibrate_t_s - date) / d.recalibrate_sigma_s);
    }
  }
  auto stats = [](const std::vector<double>& z, double* mean, double* sd) {
    *mean = 0;
    for (double v : z) *mean += v / static_cast<double>(z.size());
    double ss = 0;
    for (double v : z) ss += (v - *mean) * (v - *mean);
    *sd = std::sqrt(ss / static_cast<double>(z.size() - 1));
  };
  double mean = 0, sd = 0, date_mean = 0, date_sd = 0;
  stats(z_slope, &mean, &sd);
  stats(z_date, &date_mean, &date_sd);
  std::printf(
      "%d units: slope z mean %.3f std %.3f; date z mean %.3f std %.3f (%d dated); "
      "repeatability's 95 %% interval held the truth in %d\n",
      kUnits, mean, sd, date_mean, date_sd, resolved, repeat_covered);
  // The wander is estimated from 10 degrees of freedom: z is Student-like, std about
  // sqrt(10 / 8) = 1.12. The mean's sampling error is 0.05.
  EXPECT_LT(std::fabs(mean), 0.2);
  EXPECT_GT(sd, 0.85);
  EXPECT_LT(sd, 1.25);
  EXPECT_GT(resolved, kUnits * 9 / 10);  // the trend is about 10 sigma
  // The delta method on tolerance / slope: the date's error is skewed by the slope's 10 % error.
  EXPECT_LT(std::fabs(date_mean), 0.3);
  EXPECT_GT(date_sd, 0.8);
  EXPECT_LT(date_sd, 1.35);
  // A chi-squared interval of 2 degrees of freedom: 95 % coverage, binomial sd 1.1 %.
  EXPECT_GE(repeat_covered, kUnits * 91 / 100);
}

TEST(ParameterDrift, NoTrendGivesNoDateOnlyABound) {
  Truth truth;
  truth.slope_per_month = 0;
  std::mt19937_64 rng(7);
  const ParameterDrift d = AnalyseParameterDrift(Unit(truth, &rng), truth.tolerance);
  ASSERT_TRUE(d.ok);
  if (!d.trend_resolved) {
    EXPECT_FALSE(d.has_recalibration);
    EXPECT_GT(d.not_before_t_s, d.last_t_s);
  }
  EXPECT_FALSE(AnalyseParameterDrift({{0, 1, 0.1}, {1, 1, 0.1}}).ok);
}

}  // namespace
}  // namespace turncal
