#pragma once
// The warm-up transient of a sensor switched on at rest (issue 39 item 4; IEEE 1431's warm-up
// time): the bias settles as b(t) = settled + amplitude exp(-t / tau), and the warm-up time is
// when the transient falls below a threshold -- turncal takes the floor of the axis's Allan
// deviation (its bias stability), below which the transient cannot be told from the bias's own
// wander. Fitted to the means of bins of the recording (BinnedMeans, memory bounded whatever its
// length), weighted by their scatter about the fit (which holds the bias instability as well as
// the white noise); sigma from the Jacobian, inflated by sqrt(chi^2 / dof) when above one. A
// recording that does not start at switch-on shows no transient and says so. Pure computation.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/analysis/ieee_noise.h"

namespace turncal {

// Means of a triad's samples over bins of fixed length from the first sample. At most
// `max_bins`: when full, neighbouring bins merge and the length doubles.
class BinnedMeans {
 public:
  explicit BinnedMeans(double bin_s = 1.0, int max_bins = 1 << 15);
  // t_s: seconds from the first sample (non-decreasing).
  void Add(double t_s, const Eigen::Vector3d& v);

  double bin_s() const { return bin_s_; }
  int bins() const { return static_cast<int>(count_.size()); }
  // The bins with samples: their centres, seconds, and means of one axis.
  void Series(int axis, std::vector<double>* t_s, std::vector<double>* mean) const;

 private:
  void Merge();
  double bin_s_;
  int max_bins_;
  std::vector<Eigen::Vector3d> sum_;
  std::vector<long> count_;
};

struct WarmUpFit {
  bool ok = false;
  std::string error;
  double settled = 0.0, amplitude = 0.0, tau_s = 0.0;  // b(t) = settled + amplitude e^(-t/tau)
  double settled_sigma = 0.0, amplitude_sigma = 0.0, tau_sigma = 0.0;
  // The amplitude is at least 3 sigma from zero: a transient was seen.
  bool resolved = false;
  double threshold = 0.0;                 // the level the transient must fall below
  double time_s = 0.0, time_sigma = 0.0;  // warm-up time and its 1 sigma (resolved only)
  double bin_sigma = 0.0;                 // the scatter of a bin mean about the fit
  double chi2 = 0.0;                      // with a noise model, of the n - 3 residuals
  bool modelled = false;                  // the bins' covariance came from a noise model
  int bins = 0;
  double span_s = 0.0;
};

// The noise of the bias about the transient.
struct BinNoiseModel {
  double white = 0.0;  // N, unit/sqrt(Hz) two-sided: a T-second mean has variance N^2 / T
  std::vector<GaussMarkovPole> gauss_markov;
  double random_walk = 0.0;  // K, unit/sqrt(s), starting at switch-on
};
// From an axis's IEEE terms (N, B as Gauss-Markov processes from a tenth of `bin_s` to 100
// spans, K); the quantisation and the ramp are left out. Empty when the fit failed.
BinNoiseModel BinNoiseFromIeee(const IeeeNoiseFit& ieee, double bin_s, double span_s);

// Fits the transient to bin means (t_s their centres from switch-on, bins `bin_s` long) with
// `threshold` (> 0) for the warm-up time; `noise` null: the bins' own scatter. At least 8 bins.
WarmUpFit FitWarmUp(const std::vector<double>& t_s, const std::vector<double>& mean, double bin_s,
                    double threshold, const BinNoiseModel* noise = nullptr);

}  // namespace turncal
