#pragma once
// What free mode's fit check compares chi^2 / dof with when the values in motion are weighed with
// a noise that was itself measured (a noise meter's second: about 50 values of a magnetometer per
// axis, issue 37).
//
// Each axis's sigma^2 is off by c_a ~ chi^2_nu / nu, and a value's norm residual carries the axes'
// noise in the shares w_ia (its direction's squares, weighed by the axes' variances: a rotation
// that turns every axis along the field averages the three axes' estimates, one that keeps one
// axis along it sees only that axis's). chi^2 / dof then moves with sum_a W_a c_a (W_a the shares'
// mean over the values): its spread is an F's with nu / sum_a W_a^2 degrees of freedom. Its mean
// is each value's own E[1 / sum_a w_ia c_a] = 1 + 2 m / (nu - 2), m = mean_i sum_a w_ia^2, which
// is at least sum_a W_a^2 (0.6 over a whole sphere, where sum_a W_a^2 is 1/3): the F is scaled to
// it (600 pause rows: chi^2 / dof 1.028 where the unscaled F gave 1.017).
// Pure computation.

#include <Eigen/Core>
#include <limits>

#include "core/modeling/free_model.h"

namespace turncal {

struct MotionNoiseReference {
  double dof = std::numeric_limits<double>::infinity();  // the F's second degrees of freedom
  double scale = 1.0;  // chi^2 / dof over this is the F (FitCheck::noise_scale)
};

// The reference for `model`'s values in motion in `data` at `theta` against a noise measured with
// `nu` degrees of freedom per axis (infinite or not positive: returned as the dof, scale 1).
MotionNoiseReference MotionNoiseReferenceFor(const FreeModel& model, const FreeData& data,
                                             const Eigen::VectorXd& theta, double nu);

}  // namespace turncal
