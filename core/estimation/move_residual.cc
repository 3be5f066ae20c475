#include "core/estimation/move_residual.h"

#include <ceres/jet.h>
#include <fmt/format.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>

#include "core/frames/reference.h"
#include "core/modeling/accel_physical.h"

namespace turncal {

double MoveRecord::duration_s() const {
  double t = 0.0;
  for (double b : block_s) t += b;
  return t;
}

bool MoveRecord::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (from.is_rate() || to.is_rate()) return fail("a move joins two static poses");
  if (increment_rad.empty() || increment_rad.size() != block_s.size()) {
    return fail("a move needs one increment and one duration per block");
  }
  if (!force_mps2.empty() && force_mps2.size() != block_s.size()) {
    return fail("a move's forces must be one per block, or none");
  }
  for (std::size_t k = 0; k < block_s.size(); ++k) {
    if (!increment_rad[k].allFinite() || !(block_s[k] > 0) || !std::isfinite(block_s[k]) ||
        (!force_mps2.empty() && !force_mps2[k].allFinite())) {
      return fail(fmt::format("block {} of the move is not finite", k));
    }
  }
  return true;
}

namespace {

// Exp(-[phi x]): the frame turned by phi (a passive rotation).
Eigen::Matrix3d FrameTurn(const Eigen::Vector3d& phi) {
  const double angle = phi.norm();
  if (angle < 1e-300) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, phi / angle).toRotationMatrix().transpose();
}

// The rotation vector v with FrameTurn(v) = R.
Eigen::Vector3d FrameLog(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(Eigen::Matrix3d(R.transpose()));
  return aa.angle() * aa.axis();
}

}  // namespace

MoveResidual::MoveResidual(const MeasurementModel& model, const MoveRecord& record)
    : model_(model), record_(record), n_(model.num_parameters()) {
  set_num_residuals(3);
  mutable_parameter_block_sizes()->push_back(n_);
  iS_ = model.index_of("Sx");
  iA_ = model.index_of("alpha1");
  iE_ = model.index_of("eps_x");
  ib_ = model.index_of("bx");
  iB_ = model.index_of("Bg_xx");
  const Mat3<double>& M = model.context().mounting;
  for (const auto& f : record.force_mps2) force_q_.push_back(M.transpose() * f);
  const double T = record.duration_s();
  const Eigen::Vector3d earth = EarthRateNed(model.context().reference);
  K_ = record.to.C_p_q() * FrameTurn(earth * T) * record.from.C_p_q().transpose();
}

std::unique_ptr<MoveResidual> MoveResidual::Make(const MeasurementModel& model,
                                                 const MoveRecord& record,
                                                 const Eigen::VectorXd& theta0,
                                                 double noise_density, std::string* error) {
  if (model.sensor() != SensorKind::kGyroscope) {
    if (error) *error = "a move is a gyroscope's record";
    return nullptr;
  }
  if (!record.IsValid(error)) return nullptr;
  std::unique_ptr<MoveResidual> r(new MoveResidual(model, record));
  if (r->iS_ < 0 || r->iA_ < 0 || r->iE_ < 0 || r->ib_ < 0 ||
      theta0.size() != model.num_parameters()) {
    if (error) *error = "the gyroscope model lacks S, alpha, eps or b";
    return nullptr;
  }
  Eigen::Matrix3d qbar, qq;
  r->Rotation(theta0.data(), nullptr, &qbar, &qq);
  const double T = record.duration_s();
  const Eigen::Matrix3d tq = T * qbar;
  if (!(std::abs(tq.determinant()) > 0)) {
    if (error) *error = "the move's mean turn is singular";
    return nullptr;
  }
  // s = (T Qbar)^-1 r is measured - predicted (a bias error db makes r = +T Qbar db); the cost
  // is predicted - measured, as the static records' (core/modeling/model_adapter.h).
  r->map_ = -tq.inverse();
  r->white_ = r->map_ * (0.5 * noise_density * noise_density * qq) * r->map_.transpose();
  return r;
}

Eigen::Vector3d MoveResidual::Rotation(const double* theta, Eigen::MatrixXd* jac,
                                       Eigen::Matrix3d* qbar, Eigen::Matrix3d* qq) const {
  // G_w and dG_w / d(S, alpha, eps) by automatic differentiation.
  using Jet = ceres::Jet<double, 9>;
  Jet p[9];
  for (int i = 0; i < 3; ++i) {
    p[i] = Jet(theta[iS_ + i], i);
    p[3 + i] = Jet(theta[iA_ + i], 3 + i);
    p[6 + i] = Jet(theta[iE_ + i], 6 + i);
  }
  const Mat3<Jet> Gj =
      AccelSensorMatrix(p, p + 3) * C_q_r(p[6], p[7], p[8], model_.context().mounting);
  Eigen::Matrix3d G;
  Eigen::Matrix<double, 9, 9> dG;  // row 3i+j: d G_ij / d phys
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      G(i, j) = Gj(i, j).a;
      dG.row(3 * i + j) = Gj(i, j).v.transpose();
    }
  }
  const Eigen::Matrix3d A = G.inverse();
  const Eigen::Vector3d b(theta[ib_], theta[ib_ + 1], theta[ib_ + 2]);
  Eigen::Matrix3d B = Eigen::Matrix3d::Zero();
  if (iB_ >= 0) {
    for (int e = 0; e < 9; ++e) B(e / 3, e % 3) = theta[iB_ + e];
  }
  const std::size_t n = record_.block_s.size();
  std::vector<Eigen::Vector3d> phi(n);
  std::vector<Eigen::Matrix3d> E(n);
  Eigen::Matrix3d P = Eigen::Matrix3d::Identity();
  for (std::size_t k = 0; k < n; ++k) {
    Eigen::Vector3d u = record_.increment_rad[k] - record_.block_s[k] * b;
    if (iB_ >= 0 && !force_q_.empty()) u -= record_.block_s[k] * (B * force_q_[k]);
    phi[k] = A * u;
    E[k] = FrameTurn(phi[k]);
    P = E[k] * P;
  }
  const Eigen::Vector3d r = FrameLog(P * K_.transpose());
  if (!jac && !qbar && !qq) return r;
  Eigen::Matrix<double, 3, 9> JG = Eigen::Matrix<double, 3, 9>::Zero();
  Eigen::Matrix3d Jb = Eigen::Matrix3d::Zero();
  Eigen::Matrix<double, 3, 9> JB = Eigen::Matrix<double, 3, 9>::Zero();
  Eigen::Matrix3d sum_q = Eigen::Matrix3d::Zero(), sum_qq = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // R_{N<-k}: the turn after block k
  // d r / d phi_k = +R_{N<-k} J_k with FrameTurn(phi + d) = FrameTurn(J_k d) FrameTurn(phi),
  // J_k = I - [phi_k x] / 2 + [phi_k x]^2 / 6 (SO(3)'s left Jacobian at -phi_k, to the second
  // order: a block turns < 0.03 rad), and d phi_k = -A dG phi_k - A tau_k (db + dB f_k).
  for (std::size_t kk = n; kk-- > 0;) {
    Eigen::Matrix3d hat;
    hat << 0, -phi[kk].z(), phi[kk].y(), phi[kk].z(), 0, -phi[kk].x(), -phi[kk].y(), phi[kk].x(), 0;
    const Eigen::Matrix3d Jl = Eigen::Matrix3d::Identity() - 0.5 * hat + hat * hat / 6.0;
    const Eigen::Matrix3d Q = R * Jl * A;
    const double tau = record_.block_s[kk];
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        JG.col(3 * i + j) -= Q.col(i) * phi[kk][j];
        if (iB_ >= 0 && !force_q_.empty()) JB.col(3 * i + j) -= Q.col(i) * force_q_[kk][j] * tau;
      }
    }
    Jb -= Q * tau;
    sum_q += Q * tau;
    sum_qq += Q * Q.transpose() * tau;
    R = R * E[kk];
  }
  const double T = record_.duration_s();
  if (qbar) *qbar = sum_q / T;
  if (qq) *qq = sum_qq;
  if (jac) {
    jac->setZero(3, n_);
    const Eigen::Matrix<double, 3, 9> Jphys = JG * dG;
    for (int i = 0; i < 3; ++i) {
      jac->col(iS_ + i) = Jphys.col(i);
      jac->col(iA_ + i) = Jphys.col(3 + i);
      jac->col(iE_ + i) = Jphys.col(6 + i);
      jac->col(ib_ + i) = Jb.col(i);
    }
    if (iB_ >= 0) {
      for (int e = 0; e < 9; ++e) jac->col(iB_ + e) = JB.col(e);
    }
  }
  return r;
}

Eigen::Vector3d MoveResidual::RotationError(const Eigen::VectorXd& theta) const {
  return Rotation(theta.data(), nullptr, nullptr, nullptr);
}

bool MoveResidual::Evaluate(double const* const* parameters, double* residuals,
                            double** jacobians) const {
  Eigen::MatrixXd J;
  const bool want = jacobians != nullptr && jacobians[0] != nullptr;
  const Eigen::Vector3d r = Rotation(parameters[0], want ? &J : nullptr, nullptr, nullptr);
  if (!r.allFinite()) return false;
  const Eigen::Matrix3d W = weight_ * map_;
  Eigen::Map<Eigen::Vector3d> out_r(residuals);
  out_r = W * r;
  if (want) {
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> out(
        jacobians[0], 3, n_);
    out = W * J;
  }
  return true;
}

}  // namespace turncal
