#include "core/estimation/move_integrator.h"

#include <algorithm>
#include <cmath>

namespace turncal {

MoveIntegrator::MoveIntegrator(double period_s, double block_s)
    : period_s_(period_s),
      per_block_(std::max(1, static_cast<int>(std::lround(block_s / period_s)))) {}

void MoveIntegrator::Clear() {
  begun_ = false;
  with_force_ = true;
  record_ = MoveRecord{};
  phi_.setZero();
  force_sum_.setZero();
  in_block_ = 0;
  samples_ = 0;
  bridged_ = 0;
  acc_last_.reset();
}

void MoveIntegrator::Begin(double t_s, const Eigen::Vector3d& gyr_radps,
                           const std::optional<Eigen::Vector3d>& acc_mps2) {
  Clear();
  begun_ = true;
  record_.t_start_s = record_.t_end_s = t_s;
  gyr_last_ = gyr_radps;
  acc_last_ = acc_mps2;
  with_force_ = acc_mps2.has_value();
  samples_ = 1;
}

void MoveIntegrator::Add(double t_s, const Eigen::Vector3d& gyr_radps,
                         const std::optional<Eigen::Vector3d>& acc_mps2, int periods) {
  if (!begun_) {
    Begin(t_s, gyr_radps, acc_mps2);
    return;
  }
  const double dt = period_s_ * std::max(1, periods);
  const Eigen::Vector3d d =
      0.5 * (gyr_last_ + gyr_radps) * dt + dt * dt / 6.0 * gyr_last_.cross(gyr_radps);
  phi_ += d + 0.5 * phi_.cross(d);
  if (with_force_ && acc_mps2 && acc_last_) {
    force_sum_ += 0.5 * (*acc_last_ + *acc_mps2) * std::max(1, periods);
  } else {
    with_force_ = false;
  }
  in_block_ += std::max(1, periods);
  bridged_ += std::max(1, periods) - 1;
  gyr_last_ = gyr_radps;
  acc_last_ = acc_mps2;
  record_.t_end_s = t_s;
  ++samples_;
  if (in_block_ >= per_block_) CloseBlock();
}

void MoveIntegrator::CloseBlock() {
  if (in_block_ == 0) return;
  record_.increment_rad.push_back(phi_);
  record_.block_s.push_back(in_block_ * period_s_);
  record_.force_mps2.push_back(force_sum_ / in_block_);
  phi_.setZero();
  force_sum_.setZero();
  in_block_ = 0;
}

double MoveIntegrator::duration_s() const {
  double t = in_block_ * period_s_;
  for (double b : record_.block_s) t += b;
  return t;
}

MoveRecord MoveIntegrator::Finish(const TablePose& from, const TablePose& to) {
  CloseBlock();
  MoveRecord m = std::move(record_);
  m.from = from;
  m.to = to;
  m.samples = samples_;
  m.bridged = bridged_;
  if (!with_force_) m.force_mps2.clear();
  Clear();
  return m;
}

}  // namespace turncal
