#include "core/analysis/mount_check.h"

#include "core/frames/units.h"

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

namespace turncal {
namespace {

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * kDegPerRad;
}

double RotationAngleDeg(const Mat3<double>& r) {
  return std::acos(std::clamp(0.5 * (r.trace() - 1.0), -1.0, 1.0)) * kDegPerRad;
}

}  // namespace

Eigen::Vector3d PredictedGravityDirection(const Mat3<double>& mount, const Mat3<double>& C_p_q,
                                          const Eigen::Vector3d& g_ned) {
  return (mount * C_p_q * (-g_ned)).normalized();
}

MountCheck CheckMount(const std::vector<MountObservation>& observations,
                      const MountCheckOptions& options) {
  MountCheck out;
  std::vector<Eigen::Vector3d> u, m;
  for (const auto& o : observations) {
    if (!(o.measured.norm() > options.min_measured) || !o.measured.allFinite() ||
        !(o.predicted_case.norm() > 0.5)) {
      continue;
    }
    u.push_back(o.predicted_case.normalized());
    m.push_back(o.measured.normalized());
  }
  out.poses = static_cast<int>(u.size());
  if (u.empty()) return out;
  Eigen::Matrix3d spread = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d b = Eigen::Matrix3d::Zero();
  for (std::size_t k = 0; k < u.size(); ++k) {
    spread += u[k] * u[k].transpose();
    b += m[k] * u[k].transpose();
    out.largest_off_deg = std::max(out.largest_off_deg, AngleDeg(u[k], m[k]));
  }
  spread /= static_cast<double>(u.size());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(spread);
  out.determined = eig.eigenvalues()[1] >= options.min_spread;  // ascending: [1] the middle one
  // The RMS angle between the measured directions and D's prediction (D the identity until
  // determined).
  const auto misfit_deg = [&](const Mat3<double>& d) {
    double sum = 0;
    for (std::size_t k = 0; k < u.size(); ++k) sum += std::pow(AngleDeg(d * u[k], m[k]), 2);
    return std::sqrt(sum / static_cast<double>(u.size()));
  };
  if (!out.determined) {
    // One direction: wrong if it is already off; which rotation is not known.
    out.wrong = out.largest_off_deg > options.wrong_deg;
    out.misfit_deg = misfit_deg(Mat3<double>::Identity());
    return out;
  }
  // Kabsch: the rotation D maximising sum m_k . D u_k.
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(b, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d fix = Eigen::Matrix3d::Identity();
  fix(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  Mat3<double> d = svd.matrixU() * fix * svd.matrixV().transpose();
  const Mat3<double> nearest = NearestAxisAlignedRotation(d);
  if (RotationAngleDeg(nearest.transpose() * d) <= options.snap_deg) {
    d = nearest;
    out.snapped = true;
  }
  out.rotation = d;
  out.angle_deg = RotationAngleDeg(d);
  out.wrong = out.angle_deg > options.wrong_deg;
  out.misfit_deg = misfit_deg(d);
  return out;
}

}  // namespace turncal
