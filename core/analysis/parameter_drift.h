#pragma once
// A parameter's history over a unit's calibrations (issue 39 item 3): its turn-on-to-turn-on
// repeatability, its trend in time with a sigma, and the date the trend takes it outside a
// tolerance -- the recalibration interval, from data.
//
// The data are (time, value, sigma) per calibration, sigma the calibration's own. Two sources of
// scatter beyond sigma are told apart:
//   repeatability  the pooled standard deviation of calibrations made on the same day (a unit
//                  switched off and on between them), with its chi-squared interval: IEEE's
//                  turn-on-to-turn-on repeatability. It includes each calibration's own sigma;
//                  `repeatability_beyond` is what is left after it.
//   wander         the calibrations' scatter about a straight line in time beyond their sigma,
//                  tau^2 (Paule-Mandel: the tau^2 >= 0 at which the weighted residuals' chi^2
//                  equals its degrees of freedom).
// The trend is the weighted least squares line with weights 1 / (sigma_i^2 + tau^2), its sigma
// from (X' W X)^-1. The recalibration date is the last calibration plus tolerance / |trend|,
// with the delta method's sigma; when the trend is within 2 sigma of zero there is no date, only
// the 95 % bound it is not before. Pure computation.

#include <cmath>
#include <string>
#include <vector>

namespace turncal {

struct DriftPoint {
  double t_s = 0.0;  // calibration time, Unix seconds
  double value = 0.0;
  double sigma = 0.0;  // the calibration's own 1 sigma (0: unknown)
};

inline constexpr double kSecondsPerMonth = 30.4375 * 86400.0;  // a Julian year / 12

struct ParameterDrift {
  bool ok = false;
  std::string error;
  int calibrations = 0;
  double first_t_s = 0.0, last_t_s = 0.0;
  // Same-day groups (UTC days with two or more calibrations).
  int repeat_groups = 0, repeat_dof = 0;
  double repeatability = NAN, repeatability_low95 = NAN, repeatability_high95 = NAN;
  double repeatability_beyond = NAN;  // sqrt(max(0, repeatability^2 - mean sigma^2))
  // The trend: value = intercept + slope (t - last_t_s).
  double wander = 0.0;  // tau
  double value_at_last = 0.0, value_at_last_sigma = 0.0;
  double slope_per_s = 0.0, slope_sigma_per_s = 0.0;
  double chi2 = 0.0;  // of the weighted residuals, with dof = calibrations - 2
  int dof = 0;
  bool trend_resolved = false;  // |slope| > 2 sigma
  double PerMonth(double per_s) const { return per_s * kSecondsPerMonth; }
  // The recalibration date for `tolerance` (NAN when none was given).
  double tolerance = NAN;
  bool has_recalibration = false;
  double recalibrate_t_s = NAN, recalibrate_sigma_s = NAN;
  double not_before_t_s = NAN;  // the 95 % lower bound (with or without a date)
};

// Needs three calibrations (two for a line and one to judge it).
ParameterDrift AnalyseParameterDrift(std::vector<DriftPoint> points, double tolerance = NAN);

}  // namespace turncal
