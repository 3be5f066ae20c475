#pragma once
// Slow bias drift between poses (MODELS.md "Errors between poses are correlated in time"): the
// covariance of a triad's bias wander averaged over the poses' time windows, for the calibrator's
// generalised least squares and for the growth of a calibration's bias sigma after it was made.
//
// The wander is a first-order Gauss-Markov process (stationary 1 sigma and correlation time) plus
// a random walk, independently per axis. A pose mean sees the wander averaged over its window;
// the calibrator's bias parameter is the bias over one reference window (the latest pose's), so
// what enters each pose's error is the increment ubar_i - ubar_ref. With a flat prior on the
// turn-on bias these increments are independent of the reference bias, which makes the GLS
// estimate of b exactly the bias over the reference window (docs/ACCURACY.md "Drift").

#include <Eigen/Core>
#include <limits>
#include <string>
#include <vector>

namespace turncal {

// A time window on one clock, seconds; t1_s > t0_s.
struct TimeWindow {
  double t0_s = 0.0;
  double t1_s = 0.0;
  double duration_s() const { return t1_s - t0_s; }
  double mid_s() const { return 0.5 * (t0_s + t1_s); }
};

struct BiasDrift {
  // First-order Gauss-Markov wander: stationary 1 sigma per axis (the triad's unit) and its
  // correlation time.
  Eigen::Vector3d gm_sigma = Eigen::Vector3d::Zero();
  double gm_tau_s = 100.0;
  // Random walk: the bias variance grows by rw_density^2 per second (triad unit / sqrt(s)).
  Eigen::Vector3d rw_density = Eigen::Vector3d::Zero();
  // Warm-up after power-on: an offset of 1 sigma warmup_sigma per axis at warmup_origin_s that
  // settles as exp(-(t - origin) / warmup_tau_s). The origin is the earliest window's start when
  // not set (NaN): the first pose, which a sensor powered on earlier has already partly settled
  // by, so the model errs towards more warm-up, not less.
  Eigen::Vector3d warmup_sigma = Eigen::Vector3d::Zero();
  double warmup_tau_s = 60.0;
  double warmup_origin_s = std::numeric_limits<double>::quiet_NaN();

  bool enabled() const {
    return gm_sigma.maxCoeff() > 0 || rw_density.maxCoeff() > 0 || warmup_sigma.maxCoeff() > 0;
  }
  bool IsValid(std::string* error) const;

  // Covariance on one axis of the wander averaged over window a and over window b (the random
  // walk's part counted from time origin_s, which cancels in increments; the warm-up's from
  // warmup_origin_s, or origin_s when that is not set).
  double WindowCovariance(int axis, const TimeWindow& a, const TimeWindow& b,
                          double origin_s) const;
  // Variance on one axis of the bias at time t_s minus its average over `ref`: how far the bias
  // may have moved from a calibration's value (0 at the window's middle for short windows).
  double VarianceSince(int axis, const TimeWindow& ref, double t_s) const;
  // The 1-sigma wander per axis over `seconds` after the reference window's end.
  Eigen::Vector3d SigmaAfter(const TimeWindow& ref, double seconds) const;
  // Variance on one axis of the wander's mean over `second_s` seconds minus its mean over the
  // `first_s` seconds just before: what a still dwell's two halves may differ by through the
  // sensor's own drift (Gauss-Markov and random walk; the warm-up's slow settling is left out).
  double HalvesDifferenceVariance(int axis, double first_s, double second_s) const;
  // The window's mean of exp(-(t - origin_s) / warmup_tau_s).
  double WarmupMean(const TimeWindow& window, double origin_s) const;
};

// The windows' indices in time order (by start; ties keep their order): the last is the
// reference window of the generalised least squares.
std::vector<int> TimeOrder(const std::vector<TimeWindow>& windows);

// D(i, j) = Cov(ubar_i - ubar_ref, ubar_j - ubar_ref) on one axis for the windows given (row
// and column `ref` are zero).
Eigen::MatrixXd DriftIncrementCovariance(const BiasDrift& drift, int axis,
                                         const std::vector<TimeWindow>& windows, int ref);

}  // namespace turncal
