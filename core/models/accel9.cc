// accel9: an accelerometer without known poses (issue 22; imu_tk's model): the specific force
// f = T K (a_m - b) has the local gravity's magnitude in every static interval. Parameters kx ky
// kz (gains, nominal 1: the raw triad is taken as roughly in m/s^2), m_yz m_zy m_zx (the upper-
// triangular non-orthogonality, rad: the triad fixes its own frame), bx by bz (m/s^2). Each
// interval gives one residual, (|f| - g) / sigma, sigma the first-order deviation of |f| from the
// mean's covariance: the two directions of f that the unknown pose absorbs carry nothing.

#include <fmt/format.h>

#include "core/models/free_common.h"

namespace turncal {
namespace {

struct Accel9Correction {
  template <typename T>
  static Vec3<T> Apply(const T* p, const Vec3<T>& raw) {
    return free::UpperTK(p) * (raw - free::Vector(p + 6));
  }
};

class Accel9 final : public free::NormFreeModel {
 public:
  explicit Accel9(const FreeContext& context)
      : NormFreeModel("accel9", SensorKind::kAccelerometer, 6, context.gravity_mps2) {
    const auto G = ParameterKind::kSensor;
    for (const char* k : {"kx", "ky", "kz"}) params_.push_back({k, G, ParameterUnit::kGain, 1.0});
    for (const char* m : {"m_yz", "m_zy", "m_zx"}) {
      params_.push_back({m, G, ParameterUnit::kAngle, 0.0});
    }
    for (const char* b : {"bx", "by", "bz"}) {
      params_.push_back({b, G, ParameterUnit::kAcceleration, 0.0});
    }
  }
  std::string description() const override {
    return "accelerometer without poses: gains, upper-triangular non-orthogonality and bias "
           "from |f| = g in each static interval (imu_tk's model)";
  }
  Eigen::VectorXd Scales(const FreeData& data, const Eigen::VectorXd&) const override {
    Eigen::VectorXd s = Eigen::VectorXd::Ones(9);
    s.tail<3>().setConstant(data.context.gravity_mps2);
    return s;
  }

  bool Start(const FreeData& data, Eigen::VectorXd* theta, std::string* error) const override {
    const std::vector<Eigen::Vector3d> means = RawMeans(data);
    if (means.size() < 3) {
      if (error) {
        *error = fmt::format("accel9 needs static intervals with the accelerometer: {} found",
                             means.size());
      }
      return false;
    }
    *theta = Eigen::VectorXd::Zero(9);
    theta->head<3>().setOnes();
    // |f| = g: (a - b)^T E (a - b) = 1 with E = C^T C / g^2, C = T K upper triangular.
    if (auto e = free::FitEllipsoid(means)) {
      const Eigen::Matrix3d E = e->E * magnitude() * magnitude();
      Eigen::LLT<Eigen::Matrix3d> llt(E);
      if (llt.info() == Eigen::Success) {
        const Eigen::Matrix3d C = llt.matrixL().transpose();
        // Keep the start only when it is a plausible triad (gains within a factor of two).
        if (C.diagonal().minCoeff() > 0.5 && C.diagonal().maxCoeff() < 2.0) {
          free::UpperTKFromMatrix(C, theta->data());
          theta->tail<3>() = e->center;
        }
      }
    }
    return true;
  }

  std::vector<FreeTerm> Terms(const FreeData& data, const Eigen::VectorXd& theta) const override {
    const Eigen::Matrix3d L = free::UpperTK(theta.data());
    return NormTerms(
        data, [&](const Eigen::Vector3d& mean, const Eigen::Matrix3d& covariance, double expected) {
          const Eigen::Vector3d f = L * (mean - theta.tail<3>());
          return free::MakeNormCost<Accel9Correction, 9>(mean, expected,
                                                         free::NormSigma(L, f, covariance));
        });
  }

  Eigen::VectorXd Identity(const FreeData&) const override {
    Eigen::VectorXd t = Eigen::VectorXd::Zero(9);
    t.head<3>().setOnes();
    return t;
  }
  Eigen::Vector3d Correct(const Eigen::VectorXd& theta, const Eigen::Vector3d& raw) const override {
    return Accel9Correction::Apply(theta.data(), raw);
  }
};

}  // namespace
}  // namespace turncal

TURNCAL_REGISTER_FREE_MODEL(accel9, turncal::Accel9)
