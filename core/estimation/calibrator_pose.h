#pragma once
// The calibrator's record as it keeps it (core/estimation/calibrator.h): private to
// calibrator.cc, which solves, and calibrator_records.cc, which takes records in.

#include <ceres/cost_function.h>

#include <Eigen/Core>
#include <memory>

#include "core/estimation/bias_drift.h"
#include "core/estimation/calibrator.h"

namespace turncal {

struct Calibrator::Pose {
  WeightedPose weighted;
  bool move = false;  // a move between two poses: `raw` is its residual (pose: the destination)
  std::unique_ptr<ceres::CostFunction> cost;  // whitened by the pose's own covariance
  // With a drift model: the unwhitened residual, the pose's own (white) covariance and its window.
  std::unique_ptr<ceres::CostFunction> raw;
  Eigen::Matrix3d white = Eigen::Matrix3d::Identity();
  // The part of `white` estimated from the window's own samples, and its degrees of freedom (0:
  // none, e.g. a move's): what SampleWeightCorrection corrects (Calibrator::WeighedWhites).
  Eigen::Matrix3d white_sample = Eigen::Matrix3d::Zero();
  double white_dof = 0.0;
  TimeWindow window;       // on the sensor's clock: drift and ordering
  TimeWindow host_window;  // on the host's: when the bias holds, for corrected output
};

// Sigma^{-1/2} of the covariance V diag(variances) V^T.
inline Eigen::Matrix3d SqrtInformation(const Eigen::Matrix3d& V, const Eigen::Vector3d& variances) {
  return V * variances.cwiseInverse().cwiseSqrt().asDiagonal() * V.transpose();
}

}  // namespace turncal
