#include "core/planning/gyro_planning.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "core/frames/reference.h"
#include "core/frames/units.h"

namespace turncal {

namespace {

// The rotation vector v with Exp(-[v x]) = R (a passive turn, as core/estimation/move_residual.h).
Eigen::Vector3d FrameLog(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(Eigen::Matrix3d(R.transpose()));
  return aa.angle() * aa.axis();
}

Eigen::Matrix3d FrameTurn(const Eigen::Vector3d& v) {
  const double angle = v.norm();
  if (angle < 1e-300) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, v / angle).toRotationMatrix().transpose();
}

TableAxis AxisOf(int index) {
  return index == 0 ? TableAxis::kInner : index == 1 ? TableAxis::kMiddle : TableAxis::kOuter;
}

int IndexOf(TableAxis axis) {
  return axis == TableAxis::kInner ? 0 : axis == TableAxis::kMiddle ? 1 : 2;
}

double& Angle(TablePose& p, int index) {
  return index == 0 ? p.phi_rad : index == 1 ? p.gamma_rad : p.psi_rad;
}

}  // namespace

bool RatePlan::IsValid(std::string* error) const {
  for (double r : rates_dps) {
    if (!std::isfinite(r) || r == 0.0 || std::abs(r) > 3600.0) {
      if (error)
        *error = fmt::format(
            "a planned rate must be finite, nonzero and at most 3600 deg/s (got {:g})", r);
      return false;
    }
  }
  if (!std::isfinite(steady_s) || steady_s < 0) {
    if (error) *error = "the rate segments' steady_s must be finite and >= 0";
    return false;
  }
  return true;
}

std::vector<TablePose> RateCandidates(const RatePlan& plan, const TableMotion& motion,
                                      const std::vector<double> held_values[3]) {
  std::vector<TablePose> out;
  for (int axis = 0; axis < 3; ++axis) {
    if (!motion.continuous[axis]) continue;
    const int a = (axis + 1) % 3, b = (axis + 2) % 3;
    for (double rate : plan.rates_dps) {
      for (double va : held_values[a]) {
        for (double vb : held_values[b]) {
          TablePose p;
          Angle(p, a) = va;
          Angle(p, b) = vb;
          p.rate_axis = AxisOf(axis);
          p.rate_radps = rate * kRadPerDeg;
          out.push_back(p);
        }
      }
    }
  }
  return out;
}

double RateCaptureSeconds(double rate_radps, double dwell_s) {
  const double revolution_s = 2 * M_PI / std::abs(rate_radps);
  return std::max(1.0, std::ceil(dwell_s / revolution_s - 1e-9)) * revolution_s;
}

TablePose AfterRateSegment(const TablePose& from, const TablePose& segment) {
  TablePose at = segment;
  at.rate_axis = TableAxis::kNone;
  at.rate_radps = 0.0;
  TablePose held = from;
  const int axis = IndexOf(segment.rate_axis);
  Angle(at, axis) = Angle(held, axis);
  return at;
}

double RateSegmentSeconds(const TableMotion& motion, const RatePlan& plan, const TablePose& from,
                          const TablePose& segment, double dwell_s, double* lead_s) {
  const int axis = IndexOf(segment.rate_axis);
  const double spin_s = std::abs(segment.rate_radps) * kDegPerRad / motion.accel_dps2[axis];
  const double lead = motion.MoveSeconds(from, AfterRateSegment(from, segment)) + motion.settle_s +
                      spin_s + plan.steady_s;
  if (lead_s) *lead_s = lead;
  return lead + RateCaptureSeconds(segment.rate_radps, dwell_s) + spin_s;
}

MoveRecord PlannedMove(const MeasurementModel& model, const TableMotion& motion,
                       const TablePose& from, const TablePose& to, double rest_s) {
  MoveRecord record;
  record.from = from;
  record.to = to;
  if (from.is_rate() || to.is_rate()) return record;
  const Eigen::Vector3d travel = motion.Travel(from, to);
  const double move_s = motion.MoveSeconds(from, to);
  if (!(move_s > 0)) return record;
  const ModelContext& context = model.context();
  const Eigen::Matrix3d M = context.mounting;
  const Eigen::Vector3d earth_p = EarthRateNed(context.reference);
  const Eigen::Vector3d force_p = SpecificForceNed(context.reference);
  // A cycloid: the fraction of the travel done at t, with zero rate and acceleration at both ends.
  auto at_time = [&](double t) {
    const double u = std::clamp(t / move_s, 0.0, 1.0);
    const double s = u - std::sin(2 * M_PI * u) / (2 * M_PI);
    return TablePose{from.phi_rad + s * travel[0], from.gamma_rad + s * travel[1],
                     from.psi_rad + s * travel[2]};
  };
  // The cycloid's rate peaks at twice the mean: blocks of at most 0.1 rad at the peak (the
  // residual's Jacobian is then within 1e-3 of the sampled move's, tests/sim/gyro_planner_test.cc).
  const int blocks = std::max(8, static_cast<int>(std::ceil(2.0 * travel.norm() / 0.1)));
  const double tau = move_s / blocks;
  Eigen::Matrix3d C0 = from.C_p_q();
  double t = 0.0;
  auto add_block = [&](const Eigen::Matrix3d& C1, double seconds) {
    // The frame turn C1 Exp(-[w_E tau x]) C0^T as the increment of q's rotation, in q.
    const Eigen::Vector3d turn_q = FrameLog(C1 * FrameTurn(earth_p * seconds) * C0.transpose());
    record.increment_rad.push_back(M * turn_q);
    record.block_s.push_back(seconds);
    record.force_mps2.push_back(M * (0.5 * (C0 + C1) * force_p));
    C0 = C1;
    t += seconds;
  };
  for (int k = 1; k <= blocks; ++k) add_block(at_time(k * tau).C_p_q(), tau);
  const double rest = motion.settle_s + std::max(0.0, rest_s);
  if (rest > 0) add_block(to.C_p_q(), rest);
  record.t_start_s = 0.0;
  record.t_end_s = t;
  return record;
}

}  // namespace turncal
