#include "core/estimation/free_noise_reference.h"

#include <cmath>

namespace turncal {

MotionNoiseReference MotionNoiseReferenceFor(const FreeModel& model, const FreeData& data,
                                             const Eigen::VectorXd& theta, double nu) {
  MotionNoiseReference out;
  out.dof = nu;
  if (!std::isfinite(nu) || !(nu > 0)) return out;
  Eigen::Vector3d share = Eigen::Vector3d::Zero();
  double concentration = 0.0;
  int values = 0;
  for (const auto& iv : data.intervals) {
    if (!iv.in_motion || !iv.mag) continue;
    const Eigen::Vector3d u = model.Direction(data, theta, iv).normalized();
    if (!u.allFinite()) continue;
    const Eigen::Vector3d part = u.cwiseAbs2().cwiseProduct(iv.mag->covariance.diagonal());
    if (!(part.sum() > 0)) continue;
    const Eigen::Vector3d w = part / part.sum();
    share += w;
    concentration += w.squaredNorm();
    ++values;
  }
  if (values == 0) return out;
  share /= values;
  concentration /= values;
  out.dof = nu / share.squaredNorm();
  if (nu > 2 && out.dof > 2) {
    out.scale = (1 + 2 * concentration / (nu - 2)) * (out.dof - 2) / out.dof;
  }
  return out;
}

}  // namespace turncal
