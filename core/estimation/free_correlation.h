#pragma once
// Noise correlated from one value in motion to the next (issue 37): a magnetometer's low-pass
// filter (or a decimation filter in the device) filters the noise as well as the field, so the
// values of a continuous rotation are not independent -- a first-order filter of 10 Hz makes
// consecutive values of a 100-Hz magnetometer correlate by exp(-2 pi 10 Hz x 10 ms) = 0.53, and a
// fit that counts them as independent claims sigmas too small by about sqrt((1 + rho)/(1 - rho)).
//
// The correlation is measured, not assumed: the lag-one correlation of the values' residuals at
// the fit (each whitened by its own white noise), over the pairs of consecutive values in motion
// no further apart than three typical spacings and within 4 robust sigmas. A magnet passing is
// smooth too: the disturbed values are found and left out with the values taken as independent
// (core/estimation/free_disturbance.h), and only then is the correlation taken into the fit.
// Beyond max(min_lag_one, sigmas / sqrt(pairs)) -- white noise's lag-one correlation has the
// sigma 1 / sqrt(pairs) -- the noise is taken as exponentially correlated in time,
// corr(t_i, t_j) = exp(-|t_i - t_j| / tau): a first-order filter's, the continuous-time AR(1)
// (Ornstein-Uhlenbeck) sampled at the values' own instants, with tau such that the pairs' mean
// exp(-dt / tau) is the measured correlation. The values are then whitened together, not thinned,
// so every value keeps its information: Prais-Winsten's transform at irregular spacing,
// e_k = (r_k - phi_k r_{k-1}) / sqrt(1 - phi_k^2), phi_k = exp(-(t_k - t_{k-1}) / tau).
// Pure computation.

#include <Eigen/Core>
#include <vector>

#include "core/modeling/free_model.h"

namespace turncal {

struct MotionCorrelation {
  int pairs = 0;             // consecutive values in motion compared
  double lag_one = 0.0;      // their residuals' correlation at the fit (corrected, see below)
  double lag_one_raw = 0.0;  // as measured, before the fit's projection is allowed for
  double threshold = 0.0;    // above which the noise is taken as correlated
  double spacing_s = 0.0;    // the pairs' median spacing
  double tau_s = 0.0;        // the correlation's time constant when taken as correlated; else 0
  bool whitened = false;     // the fit whitened the values together with it
  bool correlated() const { return tau_s > 0; }
  // exp(-spacing / tau): the correlation between values one typical spacing apart.
  double at_spacing() const;
};

// One value in motion: its time (sensor clock, s) and its whitened residual at the fit.
struct MotionResidual {
  double t_s = 0.0;
  double r = 0.0;
};

// The correlation of `residuals` (any order). Fewer than 20 pairs: none measured (pairs 0).
//
// Residuals at a fit of `fitted_parameters` (0: none allowed for) are orthogonal to the fit's
// columns, which takes part of the noise's correlation out with the fit: with columns smooth over
// the correlation time (a hand's rotation against 10-ms values) the measured lag-one correlation
// is on average (n rho - p kappa) / (n - p kappa), kappa = (1 + rho) / (1 - rho) (tr(P S) of
// the projection P onto p smooth columns is p kappa), n the pairs. At rho 0.53, 9 parameters and
// 600 values that is 0.024 low, enough to leave sigma 2.5 % small and the chi^2 too small
// (measured through free mode, docs/FREE.md). The lag-one is solved from it for rho, with the
// ratio estimator's own bias for an AR(1), about -2 rho / n, added. Over 300 fits of 9 smooth
// columns to 600 values at mixed spacing (tests/core/free_correlation_test.cc): raw 0.469,
// corrected 0.4945, the noise's 0.498 (what is left, -0.004, is 2 of the mean's sigmas).
MotionCorrelation MeasureMotionCorrelation(std::vector<MotionResidual> residuals,
                                           double min_lag_one = 0.1, double sigmas = 3.5,
                                           int fitted_parameters = 0);

// One chain of correlated residuals: their rows in the stacked residual vector and their times.
struct CorrelatedChain {
  std::vector<int> rows;
  std::vector<double> t_s;
  double tau_s = 0.0;
};

// The values in motion among `terms` (one residual each; the terms' rows in order), their times
// their windows' middles, with the time constant `tau_s`.
CorrelatedChain MotionChain(const std::vector<FreeTerm>& terms, const FreeData& data, double tau_s);

// The chain's residuals in `r` (the terms' stacked residuals, each whitened by its own noise).
std::vector<MotionResidual> ChainResiduals(const CorrelatedChain& chain, const Eigen::VectorXd& r);

// Adds the chain's correlation (exp(-|dt| / tau) between distinct members) to the covariance S
// of whitened residuals (unit diagonal).
void AddChainCovariance(const CorrelatedChain& chain, Eigen::MatrixXd* S);

// The share of a chi^2's degrees of freedom left when the chain's time constant was measured from
// the residuals it whitens (free mode's fit check, FitCheck::dof_share). With tau from the
// residuals' own lag-one, the whitened chi^2 is (nearly) their plain sum of squares: whitening
// divides by 1 - rho^2 what the lag-one took out, so a chance correlation does not make the
// chi^2 smaller. A sum of squares of m correlated unit values varies as 2 (m + 2 sum_{i<j}
// rho_ij^2), not as chi^2_m's 2 m, so it is tested as chi^2 with m times
// m / (m + 2 sum_{i<j} rho_ij^2) degrees of freedom (Satterthwaite), rho_ij = exp(-|t_i - t_j| /
// tau) between the chain's members (others independent). At 600 values of a 10-Hz filter 10 and
// 20 ms apart that is 0.75 (a 600-value AR(1) with tau measured: the chi^2's sigma 39.7 against
// chi^2_600's 34.6, sqrt(600 / 0.75) = 40.0). 1 without a time constant.
double ChainChi2DofShare(const CorrelatedChain& chain, int m);

// The whitening W of residuals that are independent (unit variance) but for the chain: the
// identity, with the chain's rows replaced by the Prais-Winsten transform in time order.
Eigen::MatrixXd ChainWhitener(int m, const CorrelatedChain& chain);

}  // namespace turncal
