#include "core/planning/target_state.h"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <cmath>
#include <memory>

#include "core/estimation/move_residual.h"

namespace turncal::planning {

namespace {

// Sigma^{-1/2} of a symmetric positive definite covariance.
Eigen::Matrix3d InverseSqrt(const Eigen::Matrix3d& covariance) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(0.5 * (covariance + covariance.transpose()));
  return eig.eigenvectors() *
         eig.eigenvalues().cwiseMax(1e-300).cwiseSqrt().cwiseInverse().asDiagonal() *
         eig.eigenvectors().transpose();
}

// A record's rows from its unwhitened Jacobian (3 x N, raw units) and white covariance.
PlannedRows MakeRows(const TargetState& s, const Jacobian3& J, const Eigen::Matrix3d& white) {
  PlannedRows r;
  if (s.design) {
    r.J = J * s.scales.asDiagonal();
    r.white = white.diagonal().cwiseMax(1e-300);
  } else {
    r.J = InverseSqrt(white) * J * s.scales.asDiagonal();
  }
  return r;
}

}  // namespace

Eigen::Vector3d WhiteVariance(const Eigen::Matrix3d& sqrt_information) {
  const Eigen::Matrix3d info = sqrt_information.transpose() * sqrt_information;
  return info.inverse().diagonal().cwiseMax(1e-300);
}

double LogDetGain(const Eigen::MatrixXd& J, const Eigen::LDLT<Eigen::MatrixXd>& information) {
  if (J.rows() == 0) return 0.0;
  const Eigen::MatrixXd S = Eigen::MatrixXd::Identity(J.rows(), J.rows()) +
                            J * information.solve(Eigen::MatrixXd(J.transpose()));
  return std::log(S.determinant());
}

PlannedRows CandidateRows(const TargetState& s, const TablePose& pose, double dwell_s) {
  const PlanningTarget& t = *s.target;
  const MeasurementModel& model = *t.model;
  const int N = model.num_parameters();
  if (pose.is_rate() && !s.gyro) return PlannedRows{Eigen::MatrixXd(0, N), {}};
  Jacobian3 J;
  model.Predict(t.theta, pose, &J);
  const Eigen::Matrix3d info = t.sqrt_information.transpose() * t.sqrt_information;
  Eigen::Matrix3d white = info.inverse();
  if (pose.is_rate()) {
    const double offset = t.pose_offset_sigma * t.pose_offset_sigma;
    const double ratio = dwell_s / RateCaptureSeconds(pose.rate_radps, dwell_s);
    Eigen::Matrix3d noise = white - offset * Eigen::Matrix3d::Identity();
    noise = 0.5 * (noise + noise.transpose());
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(noise);
    const Eigen::Vector3d rate_q = model.context().mounting * pose.TableRate_q();
    white = eig.eigenvectors() * (eig.eigenvalues().cwiseMax(0.0) * ratio).asDiagonal() *
                eig.eigenvectors().transpose() +
            offset * Eigen::Matrix3d::Identity() +
            t.rate_accuracy * t.rate_accuracy * rate_q * rate_q.transpose();
  }
  return MakeRows(s, J, white);
}

PlannedRows MoveRows(const TargetState& s, const PlannerOptions& options, const TablePose& from,
                     const TablePose& to) {
  const PlanningTarget& t = *s.target;
  const MeasurementModel& model = *t.model;
  const MoveRecord record = PlannedMove(model, options.motion, from, to, options.move_rest_s);
  std::unique_ptr<MoveResidual> residual =
      record.block_s.empty()
          ? nullptr
          : MoveResidual::Make(model, record, model.nominal(), t.noise_density, nullptr);
  if (!residual) return PlannedRows{Eigen::MatrixXd(0, model.num_parameters()), {}};
  const Eigen::Matrix3d white = residual->white_covariance() + t.pose_offset_sigma *
                                                                   t.pose_offset_sigma *
                                                                   Eigen::Matrix3d::Identity();
  WeightedPose move;
  move.pose = to;
  move.raw_residual = std::move(residual);
  return MakeRows(s, RecordJacobian(model, t.theta, move), white);
}

Eigen::MatrixXd Stack(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  if (a.rows() == 0) return b;
  if (b.rows() == 0) return a;
  Eigen::MatrixXd out(a.rows() + b.rows(), a.cols());
  out << a, b;
  return out;
}

}  // namespace turncal::planning
