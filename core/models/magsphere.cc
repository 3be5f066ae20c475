// magsphere: the magnetometer's sphere (issue 22; MicroStrain's "sphere" fit), the variant for data
// that cannot carry an ellipsoid: hard iron b (3) and the sphere's radius r (the device's unit),
// h = (m - b) F / r with F the reference's field magnitude, or 1 when not known (the scale is then
// only relative). Each static interval gives (|m - b| - r) / sigma.

#include <fmt/format.h>

#include "core/models/free_common.h"

namespace turncal {
namespace {

struct SphereDistance {
  template <typename T>
  static Vec3<T> Apply(const T* p, const Vec3<T>& raw) {
    return raw - free::Vector(p);
  }
};

// |m - b| - r over the four parameters.
struct SphereFunctor {
  Eigen::Vector3d raw;
  double attenuation = 1.0;  // FreeInterval::mag_attenuation
  double inv_sigma = 1.0;
  template <typename T>
  bool operator()(const T* p, T* r) const {
    r[0] =
        ((Vec3<T>(raw.cast<T>()) - free::Vector(p)).norm() - T(attenuation) * p[3]) * T(inv_sigma);
    return true;
  }
};

class MagSphere final : public free::NormFreeModel {
 public:
  explicit MagSphere(const FreeContext& context)
      : NormFreeModel("magsphere", SensorKind::kMagnetometer, 0, free::FieldMagnitude(context)) {
    const auto S = ParameterKind::kSensor;
    for (const char* b : {"bx", "by", "bz", "r"}) {
      params_.push_back({b, S, ParameterUnit::kField, 0.0});
    }
  }
  std::string description() const override {
    return "magnetometer without poses: hard iron and one gain (a sphere fit), for data that "
           "cannot carry an ellipsoid";
  }
  Eigen::VectorXd Scales(const FreeData&, const Eigen::VectorXd& theta) const override {
    return Eigen::VectorXd::Constant(4, std::max(std::abs(theta[3]), 1e-300));
  }

  bool Start(const FreeData& data, Eigen::VectorXd* theta, std::string* error) const override {
    if (!Turned(data, error)) return false;
    const std::vector<Eigen::Vector3d> means = RawMeans(data);
    *theta = Eigen::VectorXd::Zero(4);
    if (auto s = free::FitSphere(means)) {
      theta->head<3>() = s->center;
      (*theta)[3] = s->radius;
      return true;
    }
    if (means.empty()) {
      if (error) *error = "magsphere needs static intervals with the magnetometer: none found";
      return false;
    }
    // Too few or too alike directions for a sphere: start at no hard iron and the mean radius;
    // the rank test then names what the data cannot determine.
    double r = 0;
    for (const auto& m : means) r += m.norm();
    (*theta)[3] = r / means.size();
    return true;
  }

  std::vector<FreeTerm> Terms(const FreeData& data, const Eigen::VectorXd& theta) const override {
    return NormTerms(
        data, [&](const Eigen::Vector3d& mean, const Eigen::Matrix3d& covariance, double expected) {
          const Eigen::Vector3d d = mean - theta.head<3>();
          auto* f =
              new SphereFunctor{mean, expected / magnitude(),
                                1.0 / free::NormSigma(Eigen::Matrix3d::Identity(), d, covariance)};
          return std::unique_ptr<ceres::CostFunction>(
              new ceres::AutoDiffCostFunction<SphereFunctor, 1, 4>(f));
        });
  }

  // No hard iron and the radius that leaves the raw magnitude as it is.
  Eigen::VectorXd Identity(const FreeData&) const override {
    Eigen::VectorXd t = Eigen::VectorXd::Zero(4);
    t[3] = magnitude();
    return t;
  }
  Eigen::Vector3d Correct(const Eigen::VectorXd& theta, const Eigen::Vector3d& raw) const override {
    return SphereDistance::Apply(theta.data(), raw) * (magnitude() / theta[3]);
  }
};

}  // namespace
}  // namespace turncal

TURNCAL_REGISTER_FREE_MODEL(magsphere, turncal::MagSphere)
