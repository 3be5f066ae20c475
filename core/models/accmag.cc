// accmag: the accelerometer and magnetometer together without known poses (issue 22; Kok and
// Schön 2014, the seed's reference [5]): besides |f| = g and |h| = F in every static interval, the
// angle between the two is the local dip, constant, which determines the rotation R between the
// magnetometer's triad and the accelerometer's. Parameters: accel9's nine (kx ky kz m_yz m_zy
// m_zx, bias ba_x ba_y ba_z), the magnetometer's hard iron bm_x bm_y bm_z and symmetric soft iron
// s11 ... s33, the rotation vector r_x r_y r_z (the field in the accelerometer's frame is
// R(r) S (m - bm)) and the dip (rad; up . h / |h| = -sin dip, positive where the field points
// down). Each interval with both triads gives three residuals: the two norms and the dip's, each
// whitened by its first-order deviation (the dip's from both triads' noise across their
// directions, independent of the norms' to first order).

#include <ceres/rotation.h>
#include <fmt/format.h>

#include "core/models/free_common.h"

namespace turncal {
namespace {

constexpr int kA = 0, kM = 9, kS = 12, kR = 18, kDip = 21, kN = 22;

struct AccPart {
  template <typename T>
  static Vec3<T> Apply(const T* p, const Vec3<T>& raw) {
    return free::UpperTK(p + kA) * (raw - free::Vector(p + kA + 6));
  }
};
struct MagPart {
  template <typename T>
  static Vec3<T> Apply(const T* p, const Vec3<T>& raw) {
    return free::Symmetric(p + kS) * (raw - free::Vector(p + kM));
  }
};

template <typename T>
Mat3<T> Rotation(const T* r) {
  T m[9];
  ceres::AngleAxisToRotationMatrix(r, ceres::ColumnMajorAdapter3x3(m));
  Mat3<T> R;
  R << m[0], m[3], m[6], m[1], m[4], m[7], m[2], m[5], m[8];
  return R;
}

struct DipFunctor {
  Eigen::Vector3d acc, mag;
  double inv_sigma = 1.0;
  template <typename T>
  bool operator()(const T* p, T* r) const {
    const Vec3<T> u = AccPart::Apply(p, Vec3<T>(acc.cast<T>())).normalized();
    const Vec3<T> h = (Rotation(p + kR) * MagPart::Apply(p, Vec3<T>(mag.cast<T>()))).normalized();
    r[0] = (u.dot(h) + sin(p[kDip])) * T(inv_sigma);
    return true;
  }
};

class AccMag final : public FreeModel {
 public:
  explicit AccMag(const FreeContext& context) : context_(context) {
    const auto S = ParameterKind::kSensor;
    for (const char* k : {"kx", "ky", "kz"}) params_.push_back({k, S, ParameterUnit::kGain, 1.0});
    for (const char* m : {"m_yz", "m_zy", "m_zx"}) {
      params_.push_back({m, S, ParameterUnit::kAngle, 0.0});
    }
    for (const char* b : {"ba_x", "ba_y", "ba_z"}) {
      params_.push_back({b, S, ParameterUnit::kAcceleration, 0.0});
    }
    for (const char* b : {"bm_x", "bm_y", "bm_z"}) {
      params_.push_back({b, S, ParameterUnit::kField, 0.0});
    }
    for (const char* s : {"s11", "s12", "s13", "s22", "s23", "s33"}) {
      params_.push_back({s, S, ParameterUnit::kGain, s[1] == s[2] ? 1.0 : 0.0});
    }
    for (const char* r : {"r_x", "r_y", "r_z"}) {
      params_.push_back({r, ParameterKind::kMounting, ParameterUnit::kAngle, 0.0});
    }
    params_.push_back({"dip", ParameterKind::kInstallation, ParameterUnit::kAngle, 0.0});
  }
  const std::string& name() const override { return name_; }
  std::string description() const override {
    return "accelerometer and magnetometer together without poses: accel9, the magnetometer's "
           "ellipsoid and the rotation between the triads from a constant dip angle (Kok and "
           "Schön)";
  }
  SensorKind sensor() const override { return SensorKind::kMagnetometer; }
  bool Needs(SensorKind t) const override {
    return t == SensorKind::kAccelerometer || t == SensorKind::kMagnetometer;
  }
  const std::vector<ParameterInfo>& parameters() const override { return params_; }
  std::vector<std::pair<SensorKind, int>> BiasColumns() const override {
    return {{SensorKind::kAccelerometer, kA + 6}, {SensorKind::kMagnetometer, kM}};
  }
  double magnitude() const { return free::FieldMagnitude(context_); }

  Eigen::VectorXd Scales(const FreeData& data, const Eigen::VectorXd& theta) const override {
    Eigen::VectorXd s = Eigen::VectorXd::Ones(kN);
    s.segment<3>(kA + 6).setConstant(data.context.gravity_mps2);
    const double gain = free::Symmetric(theta.data() + kS).norm() / std::sqrt(3.0);
    s.segment<3>(kM).setConstant(magnitude() / std::max(gain, 1e-300));
    s.segment<6>(kS).setConstant(gain);
    return s;
  }

  bool Start(const FreeData& data, Eigen::VectorXd* theta, std::string* error) const override {
    FreeData both = data;
    both.intervals.clear();
    for (const auto& iv : data.intervals) {
      if (iv.acc && iv.mag) both.intervals.push_back(iv);
    }
    Eigen::VectorXd a, m;
    auto accel = MakeFreeModel("accel9", context_, error);
    auto mag = MakeFreeModel("magellipsoid", context_, error);
    if (!accel || !mag || !accel->Start(both, &a, error) || !mag->Start(both, &m, error)) {
      if (error) *error = "accmag: " + *error;
      return false;
    }
    *theta = Eigen::VectorXd::Zero(kN);
    theta->segment<9>(kA) = a;
    theta->segment<9>(kM) = m;
    // u_k^T M h_k = c for all k, M = lambda R: the smallest singular vector of [vec(u h^T) -1].
    const int n = static_cast<int>(both.intervals.size());
    std::vector<Eigen::Vector3d> u(n), h(n);
    for (int k = 0; k < n; ++k) {
      u[k] = accel->Correct(a, both.intervals[k].acc->mean).normalized();
      h[k] = mag->Correct(m, both.intervals[k].mag->mean).normalized();
    }
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    if (n >= 10) {
      Eigen::MatrixXd D(n, 10);
      for (int k = 0; k < n; ++k) {
        const Eigen::Matrix3d uh = u[k] * h[k].transpose();
        for (int i = 0; i < 9; ++i) D(k, i) = uh(i / 3, i % 3);
        D(k, 9) = -1.0;
      }
      Eigen::JacobiSVD<Eigen::MatrixXd> svd(D, Eigen::ComputeFullV);
      Eigen::VectorXd v = svd.matrixV().col(9);
      Eigen::Matrix3d M;
      for (int i = 0; i < 9; ++i) M(i / 3, i % 3) = v[i];
      if (M.determinant() < 0) M = -M;
      Eigen::JacobiSVD<Eigen::Matrix3d> polar(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
      const Eigen::Matrix3d candidate = polar.matrixU() * polar.matrixV().transpose();
      if (candidate.allFinite() && candidate.determinant() > 0) R = candidate;
    }
    const Eigen::AngleAxisd aa(R);
    theta->segment<3>(kR) = aa.angle() * aa.axis();
    double c = 0;
    for (int k = 0; k < n; ++k) c += u[k].dot(R * h[k]);
    (*theta)[kDip] = n > 0 ? std::asin(std::clamp(-c / n, -1.0, 1.0)) : 0.0;
    return true;
  }

  std::vector<FreeTerm> Terms(const FreeData& data, const Eigen::VectorXd& theta) const override {
    std::vector<FreeTerm> terms;
    const Eigen::Matrix3d La = free::UpperTK(theta.data() + kA);
    const Eigen::Matrix3d Lm = free::Symmetric(theta.data() + kS);
    const Eigen::Matrix3d R = Rotation(theta.data() + kR);
    for (int k = 0; k < static_cast<int>(data.intervals.size()); ++k) {
      const FreeInterval& iv = data.intervals[k];
      if (!iv.acc || !iv.mag) continue;
      const Eigen::Matrix3d ca = MeanCovariance(*iv.acc, data.context.acc_offset_sigma);
      const Eigen::Matrix3d cm = MeanCovariance(*iv.mag, data.context.mag_offset_sigma);
      const Eigen::Vector3d f = La * (iv.acc->mean - theta.segment<3>(kA + 6));
      const Eigen::Vector3d h = R * Lm * (iv.mag->mean - theta.segment<3>(kM));
      auto add = [&](std::unique_ptr<ceres::CostFunction> cost, const char* kind) {
        FreeTerm t;
        t.cost = std::move(cost);
        t.interval = k;
        t.kind = kind;
        t.window = free::Window(iv);
        terms.push_back(std::move(t));
      };
      add(free::MakeNormCost<AccPart, kN>(iv.acc->mean, context_.gravity_mps2,
                                          free::NormSigma(La, f, ca)),
          "norm");
      add(free::MakeNormCost<MagPart, kN>(iv.mag->mean, magnitude() * iv.mag_attenuation,
                                          free::NormSigma(R * Lm, h, cm)),
          "norm");
      const Eigen::Vector3d u = f.normalized(), hn = h.normalized();
      const Eigen::Matrix3d Pu = Eigen::Matrix3d::Identity() - u * u.transpose();
      const Eigen::Matrix3d Ph = Eigen::Matrix3d::Identity() - hn * hn.transpose();
      const Eigen::Matrix3d cu = Pu * La * ca * La.transpose() * Pu / f.squaredNorm();
      const Eigen::Matrix3d ch = Ph * R * Lm * cm * Lm * R.transpose() * Ph / h.squaredNorm();
      const double var = hn.dot(cu * hn) + u.dot(ch * u);
      auto* d = new DipFunctor{iv.acc->mean, iv.mag->mean, 1.0 / std::sqrt(std::max(var, 1e-300))};
      add(std::make_unique<ceres::AutoDiffCostFunction<DipFunctor, 1, kN>>(d), "dip");
    }
    return terms;
  }

  std::vector<Misfit> Misfits(const FreeData& data, const Eigen::VectorXd& theta) const override {
    std::vector<Misfit> out;
    for (int k = 0; k < static_cast<int>(data.intervals.size()); ++k) {
      const auto& iv = data.intervals[k];
      if (!iv.acc || !iv.mag) continue;
      const Eigen::Vector3d f = AccPart::Apply(theta.data(), Eigen::Vector3d(iv.acc->mean));
      const Eigen::Vector3d h = Correct(theta, iv.mag->mean);
      out.push_back({"norm", k, f.norm() - context_.gravity_mps2});
      out.push_back({"mag norm", k, h.norm() - magnitude() * iv.mag_attenuation});
      out.push_back(
          {"dip", k,
           std::asin(std::clamp(-f.normalized().dot(h.normalized()), -1.0, 1.0)) - theta[kDip]});
    }
    return out;
  }
  Eigen::VectorXd Identity(const FreeData&) const override {
    Eigen::VectorXd t = Eigen::VectorXd::Zero(kN);
    t.head<3>().setOnes();
    t[kS] = t[kS + 3] = t[kS + 5] = 1.0;
    return t;
  }
  // The field in the accelerometer's frame.
  Eigen::Vector3d Correct(const Eigen::VectorXd& theta, const Eigen::Vector3d& raw) const override {
    return Rotation(theta.data() + kR) * MagPart::Apply(theta.data(), raw);
  }
  Eigen::Vector3d Direction(const FreeData&, const Eigen::VectorXd& theta,
                            const FreeInterval& interval) const override {
    return interval.mag ? Correct(theta, interval.mag->mean) : Eigen::Vector3d::Zero();
  }

 private:
  FreeContext context_;
  std::string name_ = "accmag";
  std::vector<ParameterInfo> params_;
};

}  // namespace
}  // namespace turncal

TURNCAL_REGISTER_FREE_MODEL(accmag, turncal::AccMag)
