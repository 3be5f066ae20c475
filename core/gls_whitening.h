#pragma once
// Generalised least squares across poses when their errors are correlated in time (bias drift,
// core/bias_drift.h): the joint covariance of all pose means' errors, its Cholesky factor, and
// one Ceres residual block per pose that is that pose's whitened innovation -- its residual
// minus what the earlier poses' residuals predict of it, in units of its own sigma. The sum of
// the blocks' squares is r^T C^-1 r, so the solver minimises the exact Gaussian likelihood; a
// robust loss acts on each pose's innovation (a bad pose stands out in its own block).

#include <ceres/cost_function.h>

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "core/bias_drift.h"

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

// Residual: sum_j weight_j * raw_j(theta) over the poses added (raw_j: a pose's unwhitened
// residual block, one parameter block of `num_parameters`). Does not own the raw blocks.
class InnovationCost final : public ceres::CostFunction {
 public:
  explicit InnovationCost(int num_parameters);
  void Add(const ceres::CostFunction* raw, const Eigen::Matrix3d& weight);
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  struct Term {
    const ceres::CostFunction* raw;
    Eigen::Matrix3d weight;
  };
  std::vector<Term> terms_;
};

}  // namespace turncal
