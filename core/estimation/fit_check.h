#pragma once
// The two-sided fit check (issue 19; MODELS.md "Noise, whitening and honest uncertainty"): chi^2
// far above its degrees of freedom means the noise model or the model is too optimistic, far
// below means the noise model is too pessimistic -- both make the reported sigma wrong. The check
// tests both tails and names the likely cause from the whitened residuals (the innovations, in
// time order): one pose that carries the excess (a bad pose), residuals that follow each other
// from pose to pose (drift the noise model does not carry), one axis of the triad that carries
// it, or the noise level as a whole.

#include <Eigen/Core>
#include <limits>
#include <string>
#include <vector>

namespace turncal {

enum class FitVerdict { kOk, kTooLarge, kTooSmall };
const char* ToString(FitVerdict verdict);

struct FitCheck {
  FitVerdict verdict = FitVerdict::kOk;
  double chi2 = 0.0;
  int dof = 0;
  double p_upper = 1.0;  // P(chi^2 >= observed) under the noise model
  double p_lower = 1.0;  // P(chi^2 <= observed)
  // Finite: the p-values are the F test's of chi^2 / dof against a noise estimated with this many
  // degrees of freedom (free mode's samples in motion, FreeCalibratorOptions::motion_noise_dof).
  double noise_dof = std::numeric_limits<double>::infinity();
  // ... of (chi^2 / dof) / noise_scale: each residual mixes the axes' measured sigma by its own
  // direction, which moves chi^2's mean beyond the F's (core/estimation/free_noise_reference.h).
  double noise_scale = 1.0;
  // Below 1: the p-values count chi^2 / dof as having dof x dof_share degrees of freedom (free
  // mode's values in motion whitened with a correlation measured from them, ChainChi2DofShare).
  double dof_share = 1.0;
  // Per axis of the triad: the squared innovations' sum over the poses, divided by its share of
  // the degrees of freedom (1 when that axis's noise is as modelled).
  Eigen::Vector3d axis_ratio = Eigen::Vector3d::Ones();
  // Lag-1 correlation of consecutive poses' innovations (pooled over the axes) and its z against
  // uncorrelated innovations (sqrt(pairs) * r).
  double lag1_correlation = 0.0;
  double lag1_z = 0.0;
  int worst_pose = -1;  // the pose (in the calibrator's order) with the largest residual
  double worst_normalized = 0.0;
  std::string cause;  // empty when the verdict is kOk

  // One sentence for warnings, gate notes and the report: "chi2/dof = 0.19 (lower-tail p =
  // 1e-8): ..., so the accelerometer's sigma are too large".
  std::string Message(const std::string& triad) const;
};

// `innovations` are the poses' whitened residuals in time order, `pose_index` their indices in
// the calibrator's order; `alpha` is the two-sided check's level per tail; a pose whose
// normalised residual sqrt(|w|^2 / 3) exceeds `outlier_threshold` and whose removal brings chi^2
// within its upper tail is named as a bad pose.
FitCheck CheckFit(const std::vector<Eigen::Vector3d>& innovations,
                  const std::vector<int>& pose_index, double chi2, int dof, double alpha,
                  double outlier_threshold);

}  // namespace turncal
