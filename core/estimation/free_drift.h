#pragma once
// The bias drift of a calibration without poses (issue 22; FreeContext's *_drift): every term of a
// free model -- an interval's norm or dip, a move's direction, a rest -- sees its triad's bias
// averaged over its own window, so the drift correlates them. Relative to the bias over a
// reference window (the latest interval, which the bias parameters then stand for), a term's
// error is G (d(window) - d(ref)), G = -d r / d b its sensitivity to an offset of the raw
// reading (minus its Jacobian's bias columns), with the covariance of the window means of
// core/estimation/bias_drift.h. The terms, each whitened by its own white noise, then have the
// covariance I + E; W = L^-1 (L L^T = I + E) whitens them together, and the solve minimises
// |W r|^2 (generalised least squares), W recomputed at each pass as the whitening is.

#include <ceres/cost_function.h>

#include <Eigen/Core>
#include <vector>

#include "core/estimation/bias_drift.h"
#include "core/estimation/free_correlation.h"
#include "core/modeling/free_model.h"

namespace turncal {

struct FreeDriftTriad {
  SensorKind triad = SensorKind::kAccelerometer;
  int bias_column = -1;  // the triad's bx in theta; -1: the model carries no bias for it
  BiasDrift drift;
};

// W for `terms` with the whitened Jacobian `J` (their rows in order): each term sees the drift of
// every triad in `triads` with a bias column over its own window (sensitivity -J's columns), and
// of the triads in its extra_drift over theirs; the reference window and the time origin of the
// random walk and warm-up (the earliest window's start). The terms' shared noise (FreeTerm::shared)
// is added too, and the correlation of the values in motion when `chain` (not null) has one
// (core/estimation/free_correlation.h); with none of these W is the identity.
Eigen::MatrixXd FreeDriftWhitener(const std::vector<FreeTerm>& terms, const Eigen::MatrixXd& J,
                                  const std::vector<FreeDriftTriad>& triads,
                                  const TimeWindow& reference, double origin_s,
                                  const CorrelatedChain* chain = nullptr);

// All terms as one residual block, W times their stacked residuals: over theta and, when any term
// uses it, the upstream block. The terms must outlive it.
class StackedFreeCost final : public ceres::CostFunction {
 public:
  StackedFreeCost(const std::vector<FreeTerm>& terms, Eigen::MatrixXd W, int n, int p);
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;
  bool uses_upstream() const { return p_ > 0; }

 private:
  const std::vector<FreeTerm>& terms_;
  Eigen::MatrixXd W_;
  int n_, p_, m_ = 0;
};

}  // namespace turncal
