#include "core/planning/table_motion.h"

#include <fmt/format.h>

#include <cmath>

#include "core/frames/units.h"

namespace turncal {

bool TableMotion::IsValid(std::string* error) const {
  for (int i = 0; i < 3; ++i) {
    if (!(rate_dps[i] > 0) || !std::isfinite(rate_dps[i]) || !(accel_dps2[i] > 0) ||
        !std::isfinite(accel_dps2[i])) {
      if (error) *error = "table rates and accelerations must be finite and > 0";
      return false;
    }
  }
  if (!(settle_s >= 0) || !std::isfinite(settle_s)) {
    if (error) *error = "the table's settle time must be finite and >= 0";
    return false;
  }
  return true;
}

Eigen::Vector3d TableMotion::Travel(const TablePose& from, const TablePose& to) const {
  const Eigen::Vector3d a(from.phi_rad, from.gamma_rad, from.psi_rad);
  const Eigen::Vector3d b(to.phi_rad, to.gamma_rad, to.psi_rad);
  Eigen::Vector3d d = b - a;
  for (int i = 0; i < 3; ++i) {
    if (!continuous[i]) continue;
    d[i] = std::remainder(d[i], 2 * M_PI);  // in [-pi, pi]
    if (d[i] == -M_PI) d[i] = M_PI;
  }
  return d;
}

double TableMotion::AxisSeconds(int axis, double angle_rad) const {
  const double d = std::abs(angle_rad) * kDegPerRad;
  if (d == 0) return 0.0;
  const double v = rate_dps[axis], a = accel_dps2[axis];
  // Triangular when the axis cannot reach its rate: d = a t^2 / 4.
  if (d <= v * v / a) return 2.0 * std::sqrt(d / a);
  return d / v + v / a;
}

std::vector<TimeWindow> TableMotion::DwellWindows(const std::vector<TablePose>& poses,
                                                  double dwell_s, const TablePose& from) const {
  std::vector<TimeWindow> out;
  TablePose at = from;
  double t = 0;
  for (const auto& p : poses) {
    t += MoveSeconds(at, p) + settle_s;
    out.push_back({t, t + dwell_s});
    t += dwell_s;
    at = p;
  }
  return out;
}

double TableMotion::MoveSeconds(const TablePose& from, const TablePose& to) const {
  const Eigen::Vector3d d = Travel(from, to);
  double t = 0;
  for (int i = 0; i < 3; ++i) t = std::max(t, AxisSeconds(i, d[i]));
  return t;
}

}  // namespace turncal
