// Records into the calibrator (core/estimation/calibrator.h): a pose record's mean and its
// covariance (floored by the white noise, with the pose-to-pose offset and, for a rate segment,
// the table's rate accuracy), a gyroscope's moves (core/estimation/move_residual.h), and the
// poses as the analysis and the planner weigh them. The solve is in calibrator.cc.

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <cmath>

#include "core/estimation/calibrator.h"
#include "core/estimation/calibrator_pose.h"
#include "core/estimation/move_residual.h"

namespace turncal {

const TriadStats* TriadFor(SensorKind sensor, const PoseRecord& record) {
  const auto& triad = sensor == SensorKind::kAccelerometer ? record.acc
                      : sensor == SensorKind::kGyroscope   ? record.gyr
                                                           : record.mag;
  return triad ? &*triad : nullptr;
}

double WhiteFloorFraction(std::int64_t count) {
  constexpr double kLeast = 0.1;
  if (count < 2) return kLeast;
  return std::max(kLeast, 1.0 - 4.0 * std::sqrt(2.0 / static_cast<double>(count)));
}

std::vector<WeightedPose> Calibrator::weighted_poses() const {
  std::vector<WeightedPose> out;
  out.reserve(poses_.size());
  for (const auto& p : poses_) out.push_back(p.weighted);
  if (!options_.drift.enabled() || poses_.empty()) return out;
  // With drift the information is not per pose; each pose is weighed here by its own white
  // covariance plus the variance of its drift from the latest pose (the marginal), which is what
  // the observability analysis and the planner use.
  std::vector<TimeWindow> windows;
  for (const auto& p : poses_) windows.push_back(p.window);
  const int ref = TimeOrder(windows).back();
  Eigen::Matrix<double, Eigen::Dynamic, 3> marginal(num_poses(), 3);
  for (int axis = 0; axis < 3; ++axis) {
    marginal.col(axis) = DriftIncrementCovariance(drift_, axis, windows, ref).diagonal();
  }
  const std::vector<Eigen::Matrix3d> white = WeighedWhites(drift_);
  for (std::size_t i = 0; i < out.size(); ++i) {
    Eigen::Matrix3d cov = white[i];
    cov.diagonal() += marginal.row(static_cast<Eigen::Index>(i)).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    out[i].sqrt_information = SqrtInformation(eig.eigenvectors(), eig.eigenvalues());
  }
  return out;
}

void Calibrator::planning_poses(std::vector<WeightedPose>* white,
                                std::vector<TimeWindow>* windows) const {
  white->clear();
  windows->clear();
  std::vector<Eigen::Matrix3d> weighed;
  if (options_.drift.enabled()) weighed = WeighedWhites(drift_);
  for (std::size_t i = 0; i < poses_.size(); ++i) {
    const Pose& p = poses_[i];
    white->push_back(p.weighted);
    if (!options_.drift.enabled()) continue;
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(weighed[i]);
    white->back().sqrt_information = SqrtInformation(eig.eigenvectors(), eig.eigenvalues());
    windows->push_back(p.window);
  }
}

bool Calibrator::add_pose(const PoseRecord& record, std::string* error) {
  auto fail = [&](const std::string& message) {
    if (error) *error = message;
    return false;
  };
  if (!model_) return fail(model_error_);
  const TriadStats* triad = TriadFor(model_->sensor(), record);
  if (triad == nullptr) {
    return fail(fmt::format("the record has no {} statistics", ToString(model_->sensor())));
  }
  const TablePose& p = record.pose;
  if (!std::isfinite(p.phi_rad) || !std::isfinite(p.gamma_rad) || !std::isfinite(p.psi_rad) ||
      !std::isfinite(p.rate_radps)) {
    return fail("the record's table angles or rate are not finite");
  }
  if (p.is_rate() && model_->sensor() != SensorKind::kGyroscope) {
    return fail(
        fmt::format("a rate segment is not a stationary pose for the {} (only a gyroscope "
                    "model uses it)",
                    ToString(model_->sensor())));
  }
  if (!triad->mean.allFinite() || !triad->covariance.allFinite() ||
      (triad->mean_covariance && !triad->mean_covariance->allFinite())) {
    return fail("the record holds a non-finite mean or covariance");
  }
  if (triad->count < 1) return fail("the record has no samples");
  const TimeWindow window{record.sensor_start_s(), record.sensor_end_s()};
  if (options_.drift.enabled() &&
      !(std::isfinite(window.t0_s) && std::isfinite(window.t1_s) && window.t1_s > window.t0_s)) {
    return fail("the drift model needs the record's time window (t_start_s < t_end_s)");
  }

  Eigen::Matrix3d sigma = SampleMeanCovariance(*triad);
  sigma = 0.5 * (sigma + sigma.transpose());
  // Averaging and drift are timed on the sensor's clock when the record has it (a simulator or
  // a replay may run the host's clock at another pace).
  const double duration_s = record.sensor_end_s() - record.sensor_start_s();
  double floor_var = 0.0;
  if (options_.noise_density > 0 && duration_s > 0) {
    floor_var = options_.noise_density * options_.noise_density / (2.0 * duration_s) *
                WhiteFloorFraction(triad->mean_covariance ? 0 : IndependentCount(*triad));
  }
  // Floor the eigenvalues (the mean is never known much better than the white noise allows), then
  // add the pose-to-pose offset variance.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(sigma);
  const Eigen::Matrix3d sample = eig.eigenvectors() *
                                 eig.eigenvalues().cwiseMax(floor_var).asDiagonal() *
                                 eig.eigenvectors().transpose();
  Eigen::Matrix3d total = sample;
  if (p.is_rate()) {
    // The table's own rate error, along the turning axis as the gyro sees it (nominally).
    const Eigen::Vector3d axis = options_.context.mounting * p.TableRate_q();
    total += options_.rate_accuracy * options_.rate_accuracy * axis * axis.transpose();
  }
  total.diagonal().array() += options_.pose_offset_sigma * options_.pose_offset_sigma;
  eig.compute(total);
  Eigen::Vector3d lambda = eig.eigenvalues();
  if (!(lambda.minCoeff() > 0) || lambda.minCoeff() < 1e-12 * lambda.maxCoeff()) {
    return fail(
        "the record's covariance is singular and no noise floor is configured "
        "(set noise_density or pose_offset_sigma)");
  }
  const double nu = SampleMeanDof(*triad);
  if (!options_.drift.enabled()) {
    // The pose's error is its own: weigh its sample covariance for its share of it (with a
    // drift model, across the poses: WeighedWhites).
    total += SampleWeightCorrection(sample, total.inverse(), nu);
    eig.compute(total);
    lambda = eig.eigenvalues();
  }
  Pose pose;
  WeightedPose& w = pose.weighted;
  w.pose = p;
  w.measured = triad->mean;
  w.sqrt_information = SqrtInformation(eig.eigenvectors(), lambda);
  pose.cost = model_->MakeResidual(p, w.measured, w.sqrt_information);
  pose.window = window;
  pose.host_window = TimeWindow{record.t_start_s, record.t_end_s};
  if (options_.drift.enabled()) {
    pose.white = eig.eigenvectors() * lambda.asDiagonal() * eig.eigenvectors().transpose();
    pose.white_sample = sample;
    pose.white_dof = nu;
    pose.raw = model_->MakeResidual(p, w.measured, Eigen::Matrix3d::Identity());
  }
  poses_.push_back(std::move(pose));
  if (record.move_in && model_->sensor() == SensorKind::kGyroscope) {
    std::string why;
    if (!add_move(*record.move_in, &why)) {
      ++moves_refused_;
      last_move_refusal_ = why;
    }
  }
  return true;
}

bool Calibrator::add_move(const MoveRecord& move, std::string* error) {
  auto fail = [&](const std::string& message) {
    if (error) *error = message;
    return false;
  };
  if (!model_) return fail(model_error_);
  if (model_->sensor() != SensorKind::kGyroscope) return fail("a move is a gyroscope's record");
  if (!(options_.noise_density > 0)) return fail("a move needs the gyro's noise_density");
  // Qbar and the white covariance at the nominal parameters (G_w the mounting): the same
  // whenever the move is added, and never an early solve's (a gyro's static poses alone see
  // only the Earth's rate, and can put G_w anywhere).
  const Eigen::VectorXd theta0 = model_->nominal();
  std::string why;
  auto raw = MoveResidual::Make(*model_, move, theta0, options_.noise_density, &why);
  if (!raw) return fail(why);
  auto weighted = MoveResidual::Make(*model_, move, theta0, options_.noise_density, &why);
  Eigen::Matrix3d white = raw->white_covariance();
  white = 0.5 * (white + white.transpose());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(white);
  const Eigen::Vector3d lambda =
      eig.eigenvalues().array() + options_.pose_offset_sigma * options_.pose_offset_sigma;
  if (!(lambda.minCoeff() > 0)) return fail("the move's covariance is singular");
  Pose pose;
  pose.move = true;
  pose.weighted.pose = move.to;
  pose.weighted.measured = Eigen::Vector3d::Zero();
  pose.weighted.sqrt_information = SqrtInformation(eig.eigenvectors(), lambda);
  weighted->SetSqrtInformation(pose.weighted.sqrt_information);
  pose.weighted.raw_residual = std::shared_ptr<const ceres::CostFunction>(
      MoveResidual::Make(*model_, move, theta0, options_.noise_density, &why).release());
  pose.cost = std::move(weighted);
  pose.raw = std::move(raw);
  pose.white = eig.eigenvectors() * lambda.asDiagonal() * eig.eigenvectors().transpose();
  pose.window = TimeWindow{move.t_start_s, move.t_end_s};
  pose.host_window = pose.window;
  poses_.push_back(std::move(pose));
  ++moves_;
  return true;
}

Eigen::Vector3d Calibrator::MeasuredMinusPredicted(const Pose& p, const Eigen::VectorXd& theta,
                                                   Jacobian3* jacobian) const {
  if (!p.move) {
    return p.weighted.measured - (jacobian ? model_->Predict(theta, p.weighted.pose, jacobian)
                                           : model_->Predict(theta, p.weighted.pose));
  }
  // The raw residual is prediction - measurement (as the static poses' raw cost).
  Eigen::Vector3d value;
  const double* parameters[] = {theta.data()};
  if (jacobian) {
    Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::RowMajor> J(3, theta.size());
    double* jacobians[] = {J.data()};
    p.raw->Evaluate(parameters, value.data(), jacobians);
    *jacobian = J;
  } else {
    p.raw->Evaluate(parameters, value.data(), nullptr);
  }
  return -value;
}

}  // namespace turncal
