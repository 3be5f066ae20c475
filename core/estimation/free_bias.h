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
// whitened axis, those in theta by central differences of the terms' Jacobians.
//
// Values whose noise correlates from one to the next (a filter in the magnetometer), fitted by
// generalised least squares with the weight Q = W'W, E[z_i z_j'] = rho_ij I: the same expansion
// of J' Q r = 0 with G = A^-1 J' Q (A = J' Q J), u_i = c_i' z_i, K = E[u u'] = rho o (c c'),
// P = G K G', M_k = G diag(c_k) rho (c_k the k-th axis' c_i over the values) gives
//   E[theta_hat - theta] = -A^-1 { sum_i (QJ)_i (tr H_i / 2 + tr(C_i P) / 2 - sum_k b_ik' M_k,i)
//                                  + sum_i C_i (P (QJ)_i - (G K Q)_i)
//                                  + sum_i sum_k b_ik (((Q o rho) c)_ik - (QJ)_i' M_k,i) }
// (M_k,i its column i, b_ik = d a_i / d z_ik the k-th row of B_i as an n-vector), which is the
// formula above when Q = rho = I. The noise's correlation with the Jacobians of the values
// around it does not average out as the values grow denser: the bias grows with the values
// while the information they add levels off.
// On one 10-second tumble of a 10-Hz filtered magnetometer sampled at 100 Hz (issue 37's
// correlated pause row, seed 7000 run 43) the generalised fit was 5-6 sigma off; the independent
// values' formula gave a bias of 1.4 sigma, this one 4.2, and with it removed bx is 1.8 sigma off
// (600 values; 6.5 sigma of bias with 900). The drift's own part of the noise (a bias common to
// many values) is left out of rho: it is the noise of each value and of its neighbours that makes
// the bias; its generalised weights are in Q.
// Pure computation.

#include <Eigen/Core>
#include <optional>

#include "core/modeling/free_model.h"

namespace turncal {

// The weights of a fit that whitens its terms together and the values' noise correlation, both
// over the model's terms at `theta` in their order (m x m).
struct NormBiasCorrelation {
  Eigen::MatrixXd weight;  // Q = W'W, W the fit's whitener
  Eigen::MatrixXd noise;   // rho: ones on the diagonal, E[z_i z_j'] = rho_ij I
};

// E[theta_hat] - theta at `theta` (parameter units), or nullopt when the model's terms are not
// one scalar norm term per interval of one triad (accmag, gyro9: not computed) or A is singular.
// `correlated` null: the values fitted as independent (Q = rho = I).
std::optional<Eigen::VectorXd> NormFitBias(const FreeModel& model, const FreeData& data,
                                           const Eigen::VectorXd& theta,
                                           const NormBiasCorrelation* correlated = nullptr);

}  // namespace turncal
