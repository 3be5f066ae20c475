#pragma once
// The magnetometer's samples in motion that something other than the sensor moved (issue 37): a
// magnet, a steel tool or a motor passing by adds a field the model cannot explain, and the
// vendors' tools fit it in silently. After a fit, each sample in motion's field magnitude
// departure from the fit (FreeModel::Misfits, "norm") is compared with the robust scatter of all
// of them (1.4826 x the median absolute deviation: the noise and the bias's wander, which the
// departures of a disturbance do not move); those beyond the larger of `sigmas` and the count's
// Bonferroni bound at 1e-3 (so that an undisturbed capture of n values loses one in a thousand
// captures) are disturbed. CalibrateFree leaves them out, fits again and judges every value at
// the new fit (a strong disturbance pulls the first), names them, and refuses the calibration
// when more than a share of the values were disturbed. A disturbance long enough to pull the fit
// and widen the scatter until nothing stands out is caught by its shape: the departures wander
// far more than they step from one value to the next (white noise and the bias's slow drift
// leave the two alike). Pure computation.

#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/modeling/free_model.h"

namespace turncal {

struct FieldDisturbance {
  int values = 0;    // left out: the disturbed and the time about them
  int detected = 0;  // of them, those beyond the bound
  int of = 0;        // samples in motion in the capture
  // The span left out on the host's clock, s after the first interval's start, and the largest
  // departure in per cent of the field (of the corrected magnitude, 1, when the field's
  // magnitude is not known) and in robust sigmas.
  double t0_s = 0.0, t1_s = 0.0;
  double largest_percent = 0.0, largest_sigmas = 0.0;

  // The share of the values beyond the bound (what refuses a calibration).
  double share() const { return of > 0 ? static_cast<double>(detected) / of : 0.0; }
};

// The samples in motion's departures at a fit: the indices into data.intervals of those
// disturbed (beyond the larger of `sigmas` and the Bonferroni bound, in robust sigmas; none when
// fewer than 20 or their scatter is zero), in order; the largest departure among them in per
// cent of the field and in robust sigmas; the departures' robust scatter and the noise of their
// steps from one value to the next (1.4826 x the median absolute step / sqrt 2), in the triad's
// unit.
struct MotionDepartures {
  std::vector<int> disturbed;
  double largest_percent = 0.0, largest_sigmas = 0.0;
  double scatter = 0.0, step_noise = 0.0;
};
MotionDepartures FindDisturbedMotion(const FreeModel& model, const FreeData& data,
                                     const Eigen::VectorXd& theta, double sigmas);

// The samples in motion a disturbance spans, in time: the disturbed values (indices into
// data.intervals) joined into runs where less than kDisturbanceJoinS apart, each run widened by
// half its span and one value's spacing on either side (its flanks, below the bound, pull the fit
// as much as its peak: a choice by time, not by the values' own departures, which would hide the
// misfit instead of removing it); in order.
constexpr double kDisturbanceJoinS = 0.25;
std::vector<int> DisturbedSpan(const FreeData& data, const std::vector<int>& disturbed);

struct FreeEstimate;
struct FreeCalibratorOptions;

// `fit` of data, then, while the samples in motion disturbed at the fit (options'
// disturbance_sigmas; 0: never) change, `fit` again without their span (DisturbedSpan; up to
// four rounds; a fit that fails keeps the last one that worked): the estimate with its
// disturbance, a warning naming it and, past max_disturbed_share, a gate reason; and a gate reason
// when the departures' scatter exceeds max_field_wander times their step noise (a disturbance too
// long to stand out). Every fit is `fit(data, false)`: the values taken as independent, as a
// disturbance is smooth and would otherwise read as correlated noise; when the last one measures
// the values' noise correlated (FreeEstimate::correlation) and options whiten it, the values kept
// are fitted once more with `fit(kept, true)`, whitened together.
FreeEstimate LeaveOutDisturbedMotion(
    const FreeModel& model, const FreeData& data, const FreeCalibratorOptions& options,
    const std::function<FreeEstimate(const FreeData&, bool whiten)>& fit);

// "the field's magnitude departed from the fit by up to 19.4 % (41 robust sigmas) in 52 of 1000
// values in motion: a magnet or steel nearby? Left out of the fit with the time about them, 98
// values between 3.80 and 4.71 s".
std::string DisturbanceText(const FieldDisturbance& d);

}  // namespace turncal
