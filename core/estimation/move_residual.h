#pragma once
// The residual of a move (issue 21, imu_tk's rotation residual with the table's known end
// attitudes): the gyro model's inverse applied to each block's raw increment,
//   phi_k = G_w^-1 (increment_k - tau_k (b_g + B_g f_k)),  f_k the specific force in q taken as
//   M^T times the raw accelerometer,
// composed in order gives the predicted turn of the table frame, P = prod_k Exp(-[phi_k x]); the
// table's angles give K = C_p^q(to) Exp(-[w_E T x]) C_p^q(from)^T (the base p turns with the
// Earth over the move's T seconds). r = Log(P K^T).
//
// A bias error db(t) over the move turns r by +T Qbar mean(db) (Qbar the blocks' mean of
// R_{N<-k} G_w^-1, R_{N<-k} the turn after block k), so the residual given to the calibrator is
// s = (T Qbar)^-1 r, with Qbar fixed when the move is added: s then sees the bias drift exactly
// as a static record over the move's window does (y - prediction = +drift), and the generalised
// least squares over all records (core/estimation/gls_whitening.h) correlates moves and poses
// through one bias process. Its white covariance is the gyro's angle random walk over the
// blocks, (N^2 / 2) sum_k tau_k Q_k Q_k^T mapped the same way (N the white density, per
// sqrt(Hz)). The increments should integrate the samples by the trapezoid rule (the samples are
// the rate at their instants): a left-point sum leaves a turn of ~1e-3 rad over a 3 s move of the
// three axes together, the composition of its first-order errors.
//
// The Jacobian is analytic, O(blocks): d r / d phi_k = +R_{N<-k} to first order in the block's
// turn (blocks of ~10 ms at table rates turn < 0.01 rad, so the error is < 1 %), chained through
// G_w^-1 and the physical parameters (automatic differentiation of G_w only).

#include <ceres/cost_function.h>

#include <memory>
#include <string>

#include "core/estimation/move_record.h"
#include "core/modeling/measurement_model.h"

namespace turncal {

class MoveResidual final : public ceres::CostFunction {
 public:
  // `model` is a gyroscope model (gyro12, gyro21) and must outlive the residual; `theta0` the
  // parameters Qbar and the covariance are computed at (the current estimate or the nominal).
  // nullptr with a message when the model is not a gyroscope or the record is invalid.
  static std::unique_ptr<MoveResidual> Make(const MeasurementModel& model, const MoveRecord& record,
                                            const Eigen::VectorXd& theta0, double noise_density,
                                            std::string* error);

  // The residual times `sqrt_information` (identity: the raw s above).
  void SetSqrtInformation(const Eigen::Matrix3d& sqrt_information) { weight_ = sqrt_information; }
  // The white covariance of s.
  const Eigen::Matrix3d& white_covariance() const { return white_; }
  // r = Log(P K^T) at theta, rad (before the mapping to s), for reports and tests.
  Eigen::Vector3d RotationError(const Eigen::VectorXd& theta) const;

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  MoveResidual(const MeasurementModel& model, const MoveRecord& record);
  // r and, with jac (3 x N), dr/dtheta; the blocks' Qbar and sum tau Q Q^T with `sums`.
  Eigen::Vector3d Rotation(const double* theta, Eigen::MatrixXd* jac, Eigen::Matrix3d* qbar,
                           Eigen::Matrix3d* qq) const;

  const MeasurementModel& model_;
  MoveRecord record_;
  std::vector<Eigen::Vector3d> force_q_;
  Eigen::Matrix3d K_ = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d map_ = Eigen::Matrix3d::Identity();  // (T Qbar)^-1
  Eigen::Matrix3d white_ = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d weight_ = Eigen::Matrix3d::Identity();
  int n_ = 0, iS_ = -1, iA_ = -1, iE_ = -1, ib_ = -1, iB_ = -1;
};

}  // namespace turncal
