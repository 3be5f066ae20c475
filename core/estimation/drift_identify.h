#pragma once
// How strong the bias drift is, from the session's own poses (issue 19, item 1): a scale s on the
// drift model's 1 sigma (Gauss-Markov, random walk and warm-up together), identified by restricted
// maximum likelihood (REML) from the pose residuals over time, with the configured drift model
// (the sensor class's, or [station]'s) as the prior: ln s ~ N(0, prior_log_sigma^2). The
// calibrator solves with the posterior's mode, so a configured profile is a prior, not a
// replacement: with few poses the prior holds, with many the data decide.
//
// REML, not plain maximum likelihood: the parameters are estimated from the same residuals, and
// REML accounts for the degrees of freedom they take (Patterson & Thompson 1971), so s is not
// biased low when the poses are few. Evaluated at the calibrator's estimate with its Jacobian
// (the model linearised there), each axis separately (the drift is independent per axis and each
// pose's white covariance is taken as its diagonal).

#include <Eigen/Core>
#include <limits>
#include <vector>

#include "core/estimation/bias_drift.h"

namespace turncal {

struct DriftScaleOptions {
  // 1 sigma of ln s a priori: a datasheet's bias instability is known to within a factor ~2.
  double prior_log_sigma = 0.7;
  double min_scale = 0.05;  // the search interval of s
  double max_scale = 20.0;
  // The poses reject the configured drift when twice the log-likelihood ratio of their estimate
  // against it exceeds this squared (2.58: 99 %).
  double reject_prior_z = 2.58;
};

struct DriftScale {
  bool identified = false;
  // The posterior's mode (the drift's 1 sigma is `scale` times the configured model's) and the
  // restricted likelihood's alone, each with the 1 sigma of ln s from the curvature at its mode
  // (inf when the poses say nothing).
  double scale = 1.0;
  double log_sigma = std::numeric_limits<double>::infinity();
  double data_scale = 1.0;
  double data_log_sigma = std::numeric_limits<double>::infinity();
  double prior_log_sigma = 0.0;
  // The likelihood ratio of data_scale against the configured 1 exceeds reject_prior_z^2; then
  // the calibrator solves with use_scale: data_scale when it is above 1, else the largest scale
  // the poses allow at 95 % (a drift under the white noise is poorly determined: erring small
  // would make the sigma optimistic). 1 otherwise.
  bool rejects_prior = false;
  double use_scale = 1.0;
};

// The drift model with every 1 sigma multiplied by `scale`.
BiasDrift ScaledDrift(const BiasDrift& drift, double scale);

// `jacobian` (3n x N) and `residuals` (3n) stacked pose by pose in the poses' own order, raw
// (unwhitened, the triad's unit); `white` each pose's white variance per axis; `windows` their
// windows. The parameters' columns must be linearly independent (no gauge).
DriftScale IdentifyDriftScale(const Eigen::MatrixXd& jacobian, const Eigen::VectorXd& residuals,
                              const std::vector<Eigen::Vector3d>& white,
                              const std::vector<TimeWindow>& windows, const BiasDrift& prior,
                              const DriftScaleOptions& options = {});

}  // namespace turncal
