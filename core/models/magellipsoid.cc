// magellipsoid: a magnetometer without known poses (issue 22; MicroStrain's and ArduPilot's
// ellipsoid): the field h = S (m - b) has a constant magnitude F in every static interval, hard
// iron b (3, the device's unit) and a symmetric soft iron S (6: s11 s12 s13 s22 s23 s33). F is the
// reference's when given (FreeContext::field_magnitude); otherwise it is fixed at 1 and S is only
// relative: the data cannot tell a larger field from a larger gain. The rotation part of a
// general soft iron is not in the model: without poses nothing fixes the triad's frame but its
// own (the joint model accmag finds it against the accelerometer's).

#include <fmt/format.h>

#include "core/models/free_common.h"

namespace turncal {
namespace {

struct EllipsoidCorrection {
  template <typename T>
  static Vec3<T> Apply(const T* p, const Vec3<T>& raw) {
    return free::Symmetric(p + 3) * (raw - free::Vector(p));
  }
};

class MagEllipsoid final : public free::NormFreeModel {
 public:
  explicit MagEllipsoid(const FreeContext& context)
      : NormFreeModel("magellipsoid", SensorKind::kMagnetometer, 0, free::FieldMagnitude(context)) {
    const auto S = ParameterKind::kSensor;
    for (const char* b : {"bx", "by", "bz"}) params_.push_back({b, S, ParameterUnit::kField, 0.0});
    for (const char* s : {"s11", "s12", "s13", "s22", "s23", "s33"}) {
      params_.push_back({s, S, ParameterUnit::kGain, s[1] == s[2] ? 1.0 : 0.0});
    }
  }
  std::string description() const override {
    return "magnetometer without poses: hard iron and symmetric soft iron from a constant field "
           "magnitude (an ellipsoid fit)";
  }
  Eigen::VectorXd Scales(const FreeData&, const Eigen::VectorXd& theta) const override {
    const double gain = free::Symmetric(theta.data() + 3).norm() / std::sqrt(3.0);
    Eigen::VectorXd s(9);
    s.head<3>().setConstant(magnitude() / std::max(gain, 1e-300));
    s.tail<6>().setConstant(gain);
    return s;
  }

  bool Start(const FreeData& data, Eigen::VectorXd* theta, std::string* error) const override {
    if (!Turned(data, error)) return false;
    const std::vector<Eigen::Vector3d> means = RawMeans(data);
    *theta = Eigen::VectorXd::Zero(9);
    if (auto e = free::FitEllipsoid(means)) {
      const Eigen::Matrix3d S = magnitude() * free::SqrtSymmetric(e->E);
      theta->head<3>() = e->center;
      const int k[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
      for (int i = 0; i < 6; ++i) (*theta)[3 + i] = S(k[i][0], k[i][1]);
      return true;
    }
    if (auto s = free::FitSphere(means)) {
      theta->head<3>() = s->center;
      (*theta)[3] = (*theta)[6] = (*theta)[8] = magnitude() / s->radius;
      return true;
    }
    if (error) {
      *error = fmt::format(
          "magellipsoid cannot start: {} static intervals with the magnetometer fit neither an "
          "ellipsoid nor a sphere",
          means.size());
    }
    return false;
  }

  std::vector<FreeTerm> Terms(const FreeData& data, const Eigen::VectorXd& theta) const override {
    const Eigen::Matrix3d L = free::Symmetric(theta.data() + 3);
    return NormTerms(
        data, [&](const Eigen::Vector3d& mean, const Eigen::Matrix3d& covariance, double expected) {
          const Eigen::Vector3d h = L * (mean - theta.head<3>());
          return free::MakeNormCost<EllipsoidCorrection, 9>(mean, expected,
                                                            free::NormSigma(L, h, covariance));
        });
  }

  Eigen::VectorXd Identity(const FreeData&) const override {
    Eigen::VectorXd t = Eigen::VectorXd::Zero(9);
    t[3] = t[6] = t[8] = 1.0;
    return t;
  }
  Eigen::Vector3d Correct(const Eigen::VectorXd& theta, const Eigen::Vector3d& raw) const override {
    return EllipsoidCorrection::Apply(theta.data(), raw);
  }
};

}  // namespace
}  // namespace turncal

TURNCAL_REGISTER_FREE_MODEL(magellipsoid, turncal::MagEllipsoid)
