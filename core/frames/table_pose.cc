#include "core/frames/table_pose.h"

#include <algorithm>
#include <cmath>

namespace turncal {

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
