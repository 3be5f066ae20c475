#pragma once
// Generalised least squares across poses when their errors are correlated in time (bias drift,
// core/estimation/bias_drift.h): the joint covariance of all pose means' errors, its Cholesky
// factor, and one Ceres residual block per pose that is that pose's whitened innovation -- its
// residual minus what the earlier poses' residuals predict of it, in units of its own sigma. The
// sum of the blocks' squares is r^T C^-1 r, so the solver minimises the exact Gaussian likelihood;
// a robust loss acts on each pose's innovation (a bad pose stands out in its own block).

#include <ceres/cost_function.h>

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "core/estimation/bias_drift.h"

namespace turncal {

struct GlsWhitening {
  std::vector<int> order;  // pose indices in time order; order.back() is the reference pose
  Eigen::MatrixXd W;       // L^-1 of the time-ordered covariance C = L L^T (3n x 3n)
  Eigen::MatrixXd C;
};

// C = blockdiag(white_i) + the drift increments relative to the latest window, per axis. False
// with *error when C is not positive definite.
bool BuildGlsWhitening(const std::vector<TimeWindow>& windows,
                       const std::vector<Eigen::Matrix3d>& white, const BiasDrift& drift,
                       GlsWhitening* out, std::string* error);

// Every pose's unwhitened residual (and Jacobian) at one parameter point, evaluated once per
// point and shared by the innovation blocks: the solver evaluates the blocks one after another at
// the same point, so the n^2 / 2 terms cost n autodiff evaluations and small products. Not
// thread-safe (the calibrator solves with one thread). Does not own the raw blocks.
class RawResidualCache {
 public:
  using RowJacobian = Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::RowMajor>;
  RawResidualCache(std::vector<const ceres::CostFunction*> raw, int num_parameters);
  // False when a raw block fails to evaluate.
  bool Evaluate(const double* theta, bool with_jacobians);
  const Eigen::Vector3d& residual(int pose) const { return r_[static_cast<std::size_t>(pose)]; }
  const RowJacobian& jacobian(int pose) const { return J_[static_cast<std::size_t>(pose)]; }

 private:
  std::vector<const ceres::CostFunction*> raw_;
  int n_params_;
  std::vector<double> theta_;
  bool valid_ = false, jacobians_ = false;
  std::vector<Eigen::Vector3d> r_;
  std::vector<RowJacobian> J_;
};

// Residual: sum_j weight_j * raw_j(theta) over the poses added, raw_j from the shared cache.
class InnovationCost final : public ceres::CostFunction {
 public:
  InnovationCost(std::shared_ptr<RawResidualCache> cache, int num_parameters);
  void Add(int pose, const Eigen::Matrix3d& weight);
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  struct Term {
    int pose;
    Eigen::Matrix3d weight;
  };
  std::shared_ptr<RawResidualCache> cache_;
  std::vector<Term> terms_;
};

}  // namespace turncal
