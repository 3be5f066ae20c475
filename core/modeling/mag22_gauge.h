#pragma once
// The gauge of mag22 (MODELS.md "The mag22 gauge"). Seed eq. 21 has two exact symmetries that
// leave every prediction unchanged:
//   1. K_' = lambda K_, dB' = dB / lambda;
//   2. G' = G (I + t K_), K_' = (I + t K_)^-1 K_, dB' = dB - t R3(beta) B_NED.
// turncal fixes them with det(K_) = 1 and dB orthogonal to u = R3(beta) B_NED.
//
// A third direction is unobservable when K_ is a multiple of I (an isotropic platform): then
// G C_p^q (R3(beta) B_NED + dB) depends only on the sum, and beta trades against dB. Near K_ = I
// (the usual case: the platform's soft iron is weak) that direction is weak, not null; see
// docs/ACCURACY.md.

#include <Eigen/Core>

#include "core/modeling/measurement_model.h"

namespace turncal {

// Moves mag22's theta along the two symmetries to the gauge: det(K_) = 1, dB . u = 0.
// Predictions are unchanged to rounding. `model` must be mag22.
void ApplyMag22Gauge(const MeasurementModel& model, Eigen::VectorXd* theta);

// The two symmetries' tangent directions at theta (22 x 2, columns in parameter units, not
// normalised): 1. dK_ = K_, ddB = -dB; 2. dG = G K_, dK_ = -K_ K_, ddB = -R3(beta) B_NED.
// The data-level null space of mag22 is their span (tests/core/observability_test.cc).
Eigen::MatrixXd Mag22NullDirections(const MeasurementModel& model, const Eigen::VectorXd& theta);

// A 22 x 20 orthonormal basis of the tangent space of the gauge constraints at theta.
Eigen::MatrixXd Mag22GaugeTangentBasis(const MeasurementModel& model, const Eigen::VectorXd& theta);

}  // namespace turncal
