#include "core/estimation/fit_check.h"

#include <fmt/format.h>

#include <boost/math/special_functions/gamma.hpp>
#include <cmath>

namespace turncal {

const char* ToString(FitVerdict verdict) {
  switch (verdict) {
    case FitVerdict::kOk:
      return "ok";
    case FitVerdict::kTooLarge:
      return "chi2_too_large";
    case FitVerdict::kTooSmall:
      return "chi2_too_small";
  }
  return "?";
}

namespace {

double UpperTail(double chi2, int dof) {
  return dof > 0 ? boost::math::gamma_q(dof / 2.0, std::max(chi2, 0.0) / 2.0) : 1.0;
}

const char* AxisName(int axis) { return axis == 0 ? "x" : axis == 1 ? "y" : "z"; }

}  // namespace

FitCheck CheckFit(const std::vector<Eigen::Vector3d>& innovations,
                  const std::vector<int>& pose_index, double chi2, int dof, double alpha,
                  double outlier_threshold) {
  FitCheck f;
  f.chi2 = chi2;
  f.dof = dof;
  if (dof <= 0 || innovations.empty()) return f;
  f.p_upper = UpperTail(chi2, dof);
  f.p_lower = boost::math::gamma_p(dof / 2.0, std::max(chi2, 0.0) / 2.0);
  const auto n = static_cast<double>(innovations.size());
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const auto& w : innovations) sum += w.cwiseAbs2();
  f.axis_ratio = sum / (dof / 3.0);
  // Lag-1 correlation pooled over the axes: sum w_k w_{k+1} / sum w_k^2.
  double cross = 0, squares = 0;
  for (std::size_t k = 0; k < innovations.size(); ++k) {
    squares += innovations[k].squaredNorm();
    if (k + 1 < innovations.size()) cross += innovations[k].dot(innovations[k + 1]);
  }
  const double pairs = 3.0 * (n - 1);
  f.lag1_correlation = squares > 0 ? cross / squares : 0.0;
  f.lag1_z = pairs > 0 ? f.lag1_correlation * std::sqrt(pairs) : 0.0;
  for (std::size_t k = 0; k < innovations.size(); ++k) {
    const double normalized = std::sqrt(innovations[k].squaredNorm() / 3.0);
    if (normalized > f.worst_normalized) {
      f.worst_normalized = normalized;
      f.worst_pose = pose_index.size() > k ? pose_index[k] : static_cast<int>(k);
    }
  }

  int axis_max = 0;
  f.axis_ratio.maxCoeff(&axis_max);
  const double per_dof = chi2 / dof;
  if (f.p_upper < alpha) {
    f.verdict = FitVerdict::kTooLarge;
    const double without = chi2 - 3.0 * f.worst_normalized * f.worst_normalized;
    if (f.worst_normalized > outlier_threshold && UpperTail(without, dof - 3) >= alpha) {
      f.cause = fmt::format(
          "pose {} alone carries the excess (normalised residual {:.1f}): a bad pose -- the "
          "table moved or was disturbed, or the announced angles are wrong",
          f.worst_pose, f.worst_normalized);
    } else if (f.lag1_z > 3.0) {
      f.cause = fmt::format(
          "the residuals follow each other from pose to pose (lag-1 correlation {:.2f}, {:.1f} "
          "sigma): bias drift larger or slower than the noise model says",
          f.lag1_correlation, f.lag1_z);
    } else if (f.axis_ratio[axis_max] > (f.axis_ratio.sum() - f.axis_ratio[axis_max]) &&
               f.axis_ratio[axis_max] > 1.5 * per_dof) {
      // More than twice the other two axes' mean.
      f.cause = fmt::format(
          "the {} axis carries most of it ({:.2f} x its modelled noise): that axis's noise is "
          "underestimated or the model does not fit it",
          AxisName(axis_max), f.axis_ratio[axis_max]);
    } else {
      f.cause =
          "the noise model underestimates the sensor's noise (white density or bias "
          "instability), or the model does not fit";
    }
  } else if (f.p_lower < alpha) {
    f.verdict = FitVerdict::kTooSmall;
    f.cause = fmt::format(
        "the residuals are smaller than the noise model says (per axis x {:.2f}, y {:.2f}, z "
        "{:.2f}): the configured noise (white density or bias instability) is too pessimistic "
        "for this sensor",
        f.axis_ratio.x(), f.axis_ratio.y(), f.axis_ratio.z());
  }
  return f;
}

std::string FitCheck::Message(const std::string& triad) const {
  switch (verdict) {
    case FitVerdict::kOk:
      return fmt::format("chi2/dof = {:.2f} (p = {:.2g}): the {}'s noise model explains the data",
                         dof > 0 ? chi2 / dof : 0.0, p_upper, triad);
    case FitVerdict::kTooLarge:
      return fmt::format(
          "chi2/dof = {:.2f} too large (upper-tail p = {:.2g}): {}; the {}'s "
          "sigma would be too small",
          chi2 / dof, p_upper, cause, triad);
    case FitVerdict::kTooSmall:
      return fmt::format(
          "chi2/dof = {:.2f} too small (lower-tail p = {:.2g}): {}; the {}'s "
          "sigma are too large",
          chi2 / dof, p_lower, cause, triad);
  }
  return "";
}

}  // namespace turncal
