#pragma once
// How many degrees of freedom an overlapping Allan or Hadamard variance has, and its confidence
// interval (issue 39 item 1). The equivalent degrees of freedom follow Greenhall & Riley,
// "Uncertainty of stability variances based on finite differences" (PTTI 2003): the estimator
// is an average of M squared d-th phase differences whose correlation, for a power-law noise
// of type alpha, comes from the noise's generalised autocovariance; edf = M sz(0)^2 / (sum over
// lags of (1 - |lag| / M) sz(lag)^2). With the edf, the variance's interval is the chi-squared
// one (NIST SP 1065 5.3): [v edf / chi2(1 - p/2), v edf / chi2(p/2)].
//
// The noise types, for rate-like data (a gyroscope's rate, an accelerometer's force):
//   alpha  2  white phase   (quantisation, Allan slope -1)
//          1  flicker phase
//          0  white rate    (angle / velocity random walk, slope -1/2)
//         -1  flicker rate  (bias instability, slope 0)
//         -2  random-walk rate (rate random walk, slope +1/2; also used for a ramp, slope +1)
// Pure computation.

#include <cstdint>

namespace turncal {

// d = 2 for the Allan variance, 3 for the Hadamard; m the cluster size and `stride` the
// samples between starting points (1: fully overlapping; m a multiple of it), n the samples.
// 0 when the recording is too short for one term.
double OverlappingEdf(int alpha, int d, std::int64_t m, std::int64_t stride, std::int64_t n);

// The noise type whose Allan variance has this log-log slope (d ln sigma^2 / d ln tau): 2 for
// slopes below -1.5 (quantisation; flicker phase, rare in inertial sensors, is not told apart),
// 0, -1 or -2 for the nearest of -1, 0, +1 above it (a ramp's +2 counts as -2).
int NoiseTypeOfSlope(double avar_slope);

struct VarianceInterval {
  double low = 0.0, high = 0.0;
};
// The two-sided `confidence` (e.g. 0.683, 0.95) interval of a variance estimated with `edf`.
VarianceInterval ChiSquaredInterval(double variance, double edf, double confidence);

}  // namespace turncal
