#pragma once
// The second-order bias of a norm fit from the noise in its values (issue 37).
//
// A norm model (magellipsoid, magsphere, accel9) fits |Correct(theta, m_i)| = F through values
// m_i that carry noise: the classic errors-in-variables least squares, whose estimate is biased at
// second order in the noise (Box 1971 for the curvature in theta; the noise's own curvature and
// its correlation with the Jacobian for the rest). Over a whole sphere the bias is a small part of
// sigma; where the coverage is weak (a figure of eight, a cap) the weakest direction's sigma and
// the bias it picks up grow together with the condition number, and 200 figure-of-eight tumbles
// showed the gains and the hard iron along the axis of the cap half a sigma low on average (the
// circle fit's radius on an arc, too long).
//
// With residuals r_i(theta, z_i) whitened in theta (1 / s_i) and in the noise (m_i = m_i0 + R_i
// z_i, R_i R_i' the value's covariance, z_i ~ N(0, I)), a_i = dr_i/dtheta, c_i = dr_i/dz_i,
// H_i = d^2 r_i / dz_i^2, B_i = d a_i / d z_i, C_i = d^2 r_i / dtheta^2, A = sum a_i a_i',
// w_i = |c_i|^2, P = A^-1 (sum w_i a_i a_i') A^-1 (the first-order covariance), expanding the
// normal equations to second order and taking the expectation gives
//   E[theta_hat - theta] = -A^-1 sum_i { a_i (tr H_i / 2 - c_i' B_i A^-1 a_i + tr(C_i P) / 2)
//                                       + C_i (P - w_i A^-1) a_i + B_i' c_i (1 - a_i' A^-1 a_i) }.
// Everything is evaluated at the estimate (the error is third order): the derivatives in z by
// central differences of the model's own terms built on values moved by +-1 sigma along each
// whitened axis, those in theta by central differences of the terms' Jacobians. The drift's
// correlation between terms (generalised least squares) is left out of this correction: it is
// the white noise of each value that makes the bias.
// Pure computation.

#include <Eigen/Core>
#include <optional>

#include "core/modeling/free_model.h"

namespace turncal {

// E[theta_hat] - theta at `theta` (parameter units), or nullopt when the model's terms are not
// one scalar norm term per interval of one triad (accmag, gyro9: not computed) or A is singular.
std::optional<Eigen::VectorXd> NormFitBias(const FreeModel& model, const FreeData& data,
                                           const Eigen::VectorXd& theta);

}  // namespace turncal
