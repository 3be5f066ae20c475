#pragma once
// How a gyroscope's scale depends on the rate (issue 21: "several rates expose non-linearity").
//
// Each rate segment's residual (measured - predicted at the estimate) along the table's rate as
// the gyro sees it, relative to that rate, is the segment's apparent scale error
//   e_i = (r_i . u_i) / |p_i|,  p_i = G_w w_table (the table's part of the prediction),
//   u_i = p_i / |p_i|,          sigma_i^2 = u_i^T Sigma_i u_i / |p_i|^2,
// with Sigma_i the record's covariance as the calibrator weighs it. A linear gyro's e_i scatter
// about zero at every rate (the fit's scale factors absorb their mean per axis); a scale that
// grows with the rate leaves the slow segments' e below the fast ones'. Reported: the weighted
// mean e per |rate| level with its sigma, the chi^2 of the level means about their common mean
// (chi^2 with levels - 1 degrees of freedom for a linear gyro), the slope of e against |rate| and
// the asymmetry (positive rates' mean minus negative rates'). The sigmas are those of the records
// (the fit removes one common mean per axis, which the slope and the asymmetry do not see).
// Pure computation.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/estimation/pose_record.h"
#include "core/modeling/measurement_model.h"

namespace turncal {

struct RateLevel {
  double rate_dps = 0.0;  // |rate|, deg/s
  int segments = 0;
  double scale_error = 0.0;  // weighted mean e (relative; 1e-6 = 1 ppm)
  double sigma = 0.0;
};

struct RateLinearity {
  int segments = 0;
  std::vector<RateLevel> levels;  // ascending |rate|
  // Two or more levels: the slope of e against |rate| (relative per deg/s) and the chi^2 test.
  bool compared = false;
  double slope_per_dps = 0.0, slope_sigma = 0.0;
  double chi2 = 0.0;
  int dof = 0;
  double p_value = 1.0;
  // Both signs present: mean e over positive rates minus over negative ones.
  bool has_asymmetry = false;
  double asymmetry = 0.0, asymmetry_sigma = 0.0;
  std::string finding;  // one sentence for reports
};

// Over the rate segments among `records` (a gyroscope model; other records are skipped), at
// `theta`. Levels are |rate| rounded to 0.1 deg/s.
RateLinearity AnalyzeRateLinearity(const MeasurementModel& model, const Eigen::VectorXd& theta,
                                   const std::vector<WeightedPose>& records);

}  // namespace turncal
