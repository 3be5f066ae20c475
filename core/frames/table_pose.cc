#include "core/frames/table_pose.h"

#include <algorithm>
#include <cmath>

namespace turncal {

const char* ToString(TableAxis axis) {
  switch (axis) {
    case TableAxis::kNone:
      return "none";
    case TableAxis::kOuter:
      return "outer";
    case TableAxis::kMiddle:
      return "middle";
    case TableAxis::kInner:
      return "inner";
  }
  return "?";
}

bool TableAxisFromString(const std::string& name, TableAxis* axis) {
  for (TableAxis a : {TableAxis::kOuter, TableAxis::kMiddle, TableAxis::kInner}) {
    if (name == ToString(a)) {
      *axis = a;
      return true;
    }
  }
  return false;
}

Mat3<double> TablePose::MeanC_p_q() const {
  // The mean of an elementary rotation over a whole revolution is the projection on its axis.
  const Eigen::Vector3d ex = Eigen::Vector3d::UnitX(), ey = Eigen::Vector3d::UnitY(),
                        ez = Eigen::Vector3d::UnitZ();
  switch (rate_axis) {
    case TableAxis::kNone:
      return C_p_q();
    case TableAxis::kOuter:
      return R1(phi_rad) * R2(gamma_rad) * (ez * ez.transpose());
    case TableAxis::kMiddle:
      return R1(phi_rad) * (ey * ey.transpose()) * R3(psi_rad);
    case TableAxis::kInner:
      return (ex * ex.transpose()) * R2(gamma_rad) * R3(psi_rad);
  }
  return C_p_q();
}

Eigen::Vector3d TablePose::TableRate_q() const {
  // omega = phi' e_x + R1(phi) gamma' e_y + R1(phi) R2(gamma) psi' e_z (frame rotations).
  switch (rate_axis) {
    case TableAxis::kNone:
      return Eigen::Vector3d::Zero();
    case TableAxis::kOuter:
      return R1(phi_rad) * R2(gamma_rad) * Eigen::Vector3d(0, 0, rate_radps);
    case TableAxis::kMiddle:
      return R1(phi_rad) * Eigen::Vector3d(0, rate_radps, 0);
    case TableAxis::kInner:
      return Eigen::Vector3d(rate_radps, 0, 0);
  }
  return Eigen::Vector3d::Zero();
}

TablePose PoseWithDownAlong(const Eigen::Vector3d& down_q, double psi_rad) {
  // The third column of C_p^q is p's down axis in q: [-sin g, cos g sin phi, cos g cos phi].
  const Eigen::Vector3d d = down_q.normalized();
  TablePose pose;
  pose.gamma_rad = -std::asin(std::clamp(d.x(), -1.0, 1.0));
  pose.phi_rad = std::atan2(d.y(), d.z());
  pose.psi_rad = psi_rad;
  return pose;
}

}  // namespace turncal
