#pragma once
// gyro9 and gyro9g: a gyroscope without known poses (issue 22; imu_tk's gyroscope residual): the
// rate w = T K (w_m - b [- B f]), T the full misalignment to the accelerometer's triad (imu_tk's
// [1 -m_yz m_zy; m_xz 1 -m_zx; -m_xy m_yx 1]), integrated over the move between two static
// intervals, must carry the direction of gravity the accelerometer (accel9's estimate) measured in
// the first to the one it measured in the second. Parameters kx ky kz (gains), m_yz m_zy m_zx m_xz
// m_xy m_yx (rad) and bx by bz (rad/s): nine for scale and misalignment, and the bias, which every
// static interval measures directly (the "+ bias" of a rest); gyro9g adds the g-sensitivity B
// (g11 ... g33, rad/s per m/s^2, row-major) against the specific force f in the accelerometer's
// calibrated frame, which a consumer gyro has at ~1e-3 rad/s per g: its bias then differs from
// one orientation to the next by more than its noise (imu_tk's recording: 0.95e-3 rad/s RMS
// between the intervals, 0.24e-3 once B is fitted).
//
// Terms:
//  - direction (2 per move): E^T (u_k - P u_{k-1}), u the accelerometer's unit specific force
//    (accel9 at its estimate, the upstream block), P the composed turn of the move's blocks, each
//    Exp(-[phi x]) with phi = T K (increment - tau (b + B f_block)), E a basis of the plane normal
//    to u_k. Its covariance: both ends' accelerometer noise across u, the gyro's angle random walk
//    over the move (the white variance per sample times the period times the move's seconds, from
//    the intervals' own sample covariance), and the Earth's turn over the move: the integral is
//    inertial, gravity turns with the Earth, by T e x u, e the Earth's horizontal rate in the
//    second interval's frame (Omega cos L, pointing where the unknown heading puts it). The
//    accelerometer's drift at both ends moves u (FreeTerm::extra_drift).
//  - rest (3 per interval): T K (w_mean - b - B f) - Omega sin(latitude) u, the Earth's rate's
//    vertical part known from gravity, the horizontal part e.
// The Earth's horizontal rate is one vector in the world of known length and unknown azimuth, so
// every rest and move of a chain of intervals joined by moves sees the same one, turned by the
// turns between them (the moves' P at theta, composed from the chain's first interval): one
// random vector per chain, (Omega cos L)^2 / 2 across gravity in that first frame, shared by all
// its terms (FreeTerm::shared) and whitened with them. Taken as independent per interval instead,
// an industrial gyro's misalignments had sigma 5 % too large (tests/core/free_calibrator_test.cc).
// A chain restarts where a move is missing (its azimuth then independent of the previous one's).

#include <ceres/rotation.h>
#include <fmt/format.h>

#include <Eigen/Cholesky>

#include "core/models/free_common.h"

namespace turncal::free_gyro {

constexpr int kAcc = 9;
template <bool kWithG>
constexpr int kParams = kWithG ? 21 : 12;

template <typename T>
Vec3<T> UnitForce(const T* a, const Eigen::Vector3d& raw) {
  return (free::UpperTK(a) * (Vec3<T>(raw.cast<T>()) - free::Vector(a + 6))).normalized();
}

// The inverse of the lower Cholesky factor of a 2 x 2 (or 3 x 3) covariance: the whitening.
template <int D>
Eigen::Matrix<double, D, D> Whitener(const Eigen::Matrix<double, D, D>& c) {
  Eigen::LLT<Eigen::Matrix<double, D, D>> llt(c);
  return llt.matrixL().solve(Eigen::Matrix<double, D, D>::Identity());
}

// b + B f for a force f in the accelerometer's calibrated frame (the raw mean through accel9).
template <bool kWithG, typename T>
Vec3<T> Bias(const T* g, const T* a, const Eigen::Vector3d& raw_force) {
  Vec3<T> b = free::Vector(g + 9);
  if constexpr (kWithG) {
    const Vec3<T> f = free::UpperTK(a) * (Vec3<T>(raw_force.cast<T>()) - free::Vector(a + 6));
    Mat3<T> B;
    B << g[12], g[13], g[14], g[15], g[16], g[17], g[18], g[19], g[20];
    b += B * f;
  }
  return b;
}

template <bool kWithG>
struct DirectionFunctor {
  Eigen::Vector3d acc_from, acc_to;
  std::vector<Eigen::Vector3d> increment;
  std::vector<double> tau;
  std::vector<Eigen::Vector3d> force;  // per block, raw (gyro9g)
  Eigen::Matrix<double, 3, 2> E;
  Eigen::Matrix2d W;
  template <typename T>
  bool operator()(const T* g, const T* a, T* r) const {
    const Mat3<T> C = free::FullTK(g);
    Vec3<T> b = free::Vector(g + 9);
    Vec3<T> v = UnitForce(a, acc_from);
    for (std::size_t j = 0; j < increment.size(); ++j) {
      if constexpr (kWithG) b = Bias<kWithG>(g, a, force[j]);
      const Vec3<T> phi = -(C * (Vec3<T>(increment[j].cast<T>()) - T(tau[j]) * b));
      Vec3<T> w;
      ceres::AngleAxisRotatePoint(phi.data(), v.data(), w.data());
      v = w;
    }
    const Vec3<T> d = UnitForce(a, acc_to) - v;
    const Eigen::Matrix<T, 2, 1> e = W.cast<T>() * (E.transpose().cast<T>() * d);
    r[0] = e[0];
    r[1] = e[1];
    return true;
  }
};

template <bool kWithG>
struct RestFunctor {
  Eigen::Vector3d gyr, acc;
  double vertical_radps = 0.0;
  Eigen::Matrix3d W;
  template <typename T>
  bool operator()(const T* g, const T* a, T* r) const {
    const Vec3<T> w = free::FullTK(g) * (Vec3<T>(gyr.cast<T>()) - Bias<kWithG>(g, a, acc)) -
                      T(vertical_radps) * UnitForce(a, acc);
    const Vec3<T> e = W.cast<T>() * w;
    for (int i = 0; i < 3; ++i) r[i] = e[i];
    return true;
  }
};

template <bool kWithG>
class GyroFree final : public FreeModel {
 public:
  static constexpr int kGyr = kParams<kWithG>;
  explicit GyroFree(const FreeContext& context)
      : context_(context), name_(kWithG ? "gyro9g" : "gyro9") {
    const auto S = ParameterKind::kSensor;
    for (const char* k : {"kx", "ky", "kz"}) params_.push_back({k, S, ParameterUnit::kGain, 1.0});
    for (const char* m : {"m_yz", "m_zy", "m_zx", "m_xz", "m_xy", "m_yx"}) {
      params_.push_back({m, S, ParameterUnit::kAngle, 0.0});
    }
    for (const char* b : {"bx", "by", "bz"}) {
      params_.push_back({b, S, ParameterUnit::kAngularRate, 0.0});
    }
    for (int i = 0; kWithG && i < 9; ++i) {
      params_.push_back({"g" + std::to_string(i / 3 + 1) + std::to_string(i % 3 + 1), S,
                         ParameterUnit::kGSensitivity, 0.0});
    }
  }
  const std::string& name() const override { return name_; }
  std::string description() const override {
    return kWithG
               ? "gyroscope without poses: gyro9 and the g-sensitivity (3 x 3) against the "
                 "specific force, for a gyro whose bias moves with its orientation (needs accel9)"
               : "gyroscope without poses: gains, misalignment to the accelerometer and bias, "
                 "from the turn between static intervals against gravity's direction (imu_tk's "
                 "residual; needs accel9)";
  }
  SensorKind sensor() const override { return SensorKind::kGyroscope; }
  bool Needs(SensorKind t) const override {
    return t == SensorKind::kGyroscope || t == SensorKind::kAccelerometer;
  }
  std::string upstream() const override { return "accel9"; }
  const std::vector<ParameterInfo>& parameters() const override { return params_; }
  std::vector<std::pair<SensorKind, int>> BiasColumns() const override {
    return {{SensorKind::kGyroscope, 9}};
  }

  Eigen::VectorXd Scales(const FreeData& data, const Eigen::VectorXd&) const override {
    Eigen::VectorXd s = Eigen::VectorXd::Ones(kGyr);
    if constexpr (kWithG) s.tail<9>().setConstant(1.0 / data.context.gravity_mps2);
    return s;
  }

  bool Start(const FreeData& data, Eigen::VectorXd* theta, std::string* error) const override {
    if (data.upstream_theta.size() != kAcc) {
      if (error) *error = "gyro9 needs accel9's estimate (calibrate the accelerometer first)";
      return false;
    }
    *theta = Eigen::VectorXd::Zero(kGyr);
    theta->head<3>().setOnes();
    // The bias from the longest rest.
    double longest = 0;
    int moves = 0;
    for (const auto& iv : data.intervals) {
      if (iv.gyr && iv.duration_s() > longest) {
        longest = iv.duration_s();
        theta->segment<3>(9) = iv.gyr->mean;
      }
      moves += iv.move_in && iv.acc && iv.gyr;
    }
    if (moves == 0) {
      if (error) *error = "gyro9 needs moves between static intervals with both triads: none";
      return false;
    }
    return true;
  }

  std::vector<FreeTerm> Terms(const FreeData& data, const Eigen::VectorXd& theta) const override {
    std::vector<FreeTerm> terms;
    if (data.upstream_theta.size() != kAcc) return terms;
    const double* a = data.upstream_theta.data();
    const Eigen::Matrix3d La = free::UpperTK(a);
    const Eigen::Matrix3d Lg = free::FullTK(theta.data());
    const Eigen::Vector3d ba = data.upstream_theta.tail<3>();
    const double omega = context_.earth_rate_radps;
    const double lat = context_.latitude_deg * M_PI / 180;
    const double earth_h = omega * std::cos(lat);  // the Earth's rate's horizontal part
    // The gyro's white variance per sample and the sample period, from the intervals: medians.
    std::vector<double> var, period;
    for (const auto& iv : data.intervals) {
      if (!iv.gyr || iv.gyr->count < 10) continue;
      var.push_back((Lg * iv.gyr->covariance * Lg.transpose()).trace() / 3);
      period.push_back(iv.duration_s() / static_cast<double>(iv.gyr->count - 1));
    }
    auto median = [](std::vector<double> v) {
      if (v.empty()) return 0.0;
      std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
      return v[v.size() / 2];
    };
    const double arw_per_s = median(var) * median(period);  // rad^2 per second of integration
    // The unit force at an interval and its covariance across it.
    auto unit = [&](const TriadStats& s, Eigen::Vector3d* u) {
      const Eigen::Vector3d f = La * (s.mean - ba);
      *u = f.normalized();
      const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - *u * u->transpose();
      return Eigen::Matrix3d(P * La * MeanCovariance(s, data.context.acc_offset_sigma) *
                             La.transpose() * P / f.squaredNorm());
    };
    // The Earth's horizontal rate is one vector in the world, of known length and unknown heading:
    // every interval of a chain of intervals joined by moves sees it turned by the turns the gyro
    // measured (Q, from the chain's first interval's frame to this one's), so all of them share
    // it (a random vector, covariance h^2/2 across gravity in the first frame). A chain restarts
    // where a move is missing; its heading is then independent of the previous chain's.
    int chain_key = -1;
    Eigen::Matrix3d Q = Eigen::Matrix3d::Identity();
    Eigen::Matrix3d chain_cov = Eigen::Matrix3d::Zero();
    const FreeInterval* prev = nullptr;
    for (int k = 0; k < static_cast<int>(data.intervals.size()); ++k) {
      const FreeInterval& iv = data.intervals[k];
      if (!iv.acc) {
        prev = nullptr;
        continue;
      }
      Eigen::Vector3d u1;
      const Eigen::Matrix3d cov1 = unit(*iv.acc, &u1);
      const bool moved = prev && iv.move_in && !iv.move_in->increment_rad.empty();
      // The turn of the move at theta (from the previous interval's frame to this one's), to
      // carry the first end's covariance to the second and the Earth's rate along the chain.
      Eigen::Matrix3d P = Eigen::Matrix3d::Identity();
      if (moved) {
        const MoveRecord& m = *iv.move_in;
        for (std::size_t j = 0; j < m.increment_rad.size(); ++j) {
          const Eigen::Vector3d phi =
              -(Lg * (m.increment_rad[j] - m.block_s[j] * BiasAt(data, theta, m, j, *prev)));
          const double angle = phi.norm();
          const Eigen::Matrix3d R = angle > 0
                                        ? Eigen::AngleAxisd(angle, phi / angle).toRotationMatrix()
                                        : Eigen::Matrix3d::Identity();
          P = R * P;
        }
      }
      if (!moved || chain_key < 0) {
        chain_key = k;
        Q.setIdentity();
        chain_cov = earth_h * earth_h / 2 * (Eigen::Matrix3d::Identity() - u1 * u1.transpose());
      } else {
        Q = P * Q;
      }
      if (iv.gyr && iv.gyr->count > 1) {
        auto* f = new RestFunctor<kWithG>;
        f->gyr = iv.gyr->mean;
        f->acc = iv.acc->mean;
        f->vertical_radps = omega * std::sin(lat);
        const Eigen::Matrix3d c =
            Lg * MeanCovariance(*iv.gyr, data.context.gyr_offset_sigma) * Lg.transpose();
        f->W = Whitener<3>(c);
        FreeTerm t;
        // The Earth's horizontal rate in this interval's frame: the chain's, turned by Q.
        t.shared.push_back({chain_key, Eigen::MatrixXd(f->W * Q), chain_cov});
        t.cost =
            std::make_unique<ceres::AutoDiffCostFunction<RestFunctor<kWithG>, 3, kGyr, kAcc>>(f);
        t.upstream = true;
        t.interval = k;
        t.kind = "rest";
        t.window = free::Window(iv);
        terms.push_back(std::move(t));
      }
      if (moved) {
        const MoveRecord& m = *iv.move_in;
        Eigen::Vector3d u0;
        const Eigen::Matrix3d cov0 = unit(*prev->acc, &u0);
        const double T = m.duration_s();
        const Eigen::Matrix3d across = Eigen::Matrix3d::Identity() - u1 * u1.transpose();
        const Eigen::Matrix3d c = cov1 + P * cov0 * P.transpose() + arw_per_s * T * across;
        auto* f = new DirectionFunctor<kWithG>;
        f->acc_from = prev->acc->mean;
        f->acc_to = iv.acc->mean;
        f->increment = m.increment_rad;
        f->tau = m.block_s;
        if constexpr (kWithG) {
          // Blocks without a force (a device without an accelerometer in the move): the interval's.
          f->force = m.force_mps2.size() == m.block_s.size()
                         ? m.force_mps2
                         : std::vector<Eigen::Vector3d>(m.block_s.size(), prev->acc->mean);
        }
        // A basis of the plane normal to u1.
        const Eigen::Vector3d any =
            std::abs(u1.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
        f->E.col(0) = u1.cross(any).normalized();
        f->E.col(1) = u1.cross(f->E.col(0));
        f->W = Whitener<2>(f->E.transpose() * c * f->E);
        FreeTerm t;
        t.cost =
            std::make_unique<ceres::AutoDiffCostFunction<DirectionFunctor<kWithG>, 2, kGyr, kAcc>>(
                f);
        t.upstream = true;
        t.interval = k;
        t.kind = "direction";
        t.window = TimeWindow{m.t_start_s, m.t_end_s};
        // The integral is inertial: over the move the Earth turns gravity by T e x u against it,
        // e the Earth's horizontal rate in this interval's frame (shared with its rest; the
        // vertical part leaves u as it is), the residual by -T [u x] e.
        Eigen::Matrix3d ux;
        ux << 0, -u1.z(), u1.y(), u1.z(), 0, -u1.x(), -u1.y(), u1.x(), 0;
        t.shared.push_back(
            {chain_key, Eigen::MatrixXd(f->W * f->E.transpose() * (-T) * ux * Q), chain_cov});
        // The accelerometer's drift at both ends moves gravity's measured direction:
        // d u / d a = (I - u u^T) L_a / |f|.
        const Eigen::Matrix<double, 2, 3> WE = f->W * f->E.transpose();
        const double f1 = (La * (iv.acc->mean - ba)).norm();
        const double f0 = (La * (prev->acc->mean - ba)).norm();
        t.extra_drift.push_back(
            {SensorKind::kAccelerometer, free::Window(iv),
             WE * (Eigen::Matrix3d::Identity() - u1 * u1.transpose()) * La / f1});
        t.extra_drift.push_back(
            {SensorKind::kAccelerometer, free::Window(*prev),
             -WE * P * (Eigen::Matrix3d::Identity() - u0 * u0.transpose()) * La / f0});
        terms.push_back(std::move(t));
      }
      prev = &iv;
    }
    return terms;
  }

  // The angle between gravity's direction in an interval and the one the corrected gyro carried
  // the previous interval's to.
  std::vector<Misfit> Misfits(const FreeData& data, const Eigen::VectorXd& theta) const override {
    std::vector<Misfit> out;
    if (data.upstream_theta.size() != kAcc) return out;
    const Eigen::Matrix3d La = free::UpperTK(data.upstream_theta.data());
    const Eigen::Vector3d ba = data.upstream_theta.tail<3>();
    const Eigen::Matrix3d Lg = free::FullTK(theta.data());
    for (int k = 1; k < static_cast<int>(data.intervals.size()); ++k) {
      const auto& a = data.intervals[k - 1];
      const auto& b = data.intervals[k];
      if (!a.acc || !b.acc || !b.move_in || b.move_in->increment_rad.empty()) continue;
      Eigen::Vector3d v = (La * (a.acc->mean - ba)).normalized();
      const MoveRecord& m = *b.move_in;
      for (std::size_t j = 0; j < m.increment_rad.size(); ++j) {
        const Eigen::Vector3d phi =
            -(Lg * (m.increment_rad[j] - m.block_s[j] * BiasAt(data, theta, m, j, a)));
        const double angle = phi.norm();
        if (angle > 0) v = Eigen::AngleAxisd(angle, phi / angle) * v;
      }
      const Eigen::Vector3d u = (La * (b.acc->mean - ba)).normalized();
      out.push_back({"direction", k, std::atan2(u.cross(v).norm(), u.dot(v))});
    }
    return out;
  }
  Eigen::VectorXd Identity(const FreeData&) const override {
    Eigen::VectorXd t = Eigen::VectorXd::Zero(kGyr);
    t.head<3>().setOnes();
    return t;
  }
  // Without the specific force (a rate alone): the bias only.
  Eigen::Vector3d Correct(const Eigen::VectorXd& theta, const Eigen::Vector3d& raw) const override {
    return free::FullTK(theta.data()) * (raw - theta.segment<3>(9));
  }
  // b + B f over block j of a move (f the block's force, or the interval's before it).
  Eigen::Vector3d BiasAt(const FreeData& data, const Eigen::VectorXd& theta, const MoveRecord& m,
                         std::size_t j, const FreeInterval& from) const {
    const Eigen::Vector3d force =
        m.force_mps2.size() == m.block_s.size() ? m.force_mps2[j] : from.acc->mean;
    return Bias<kWithG>(theta.data(), data.upstream_theta.data(), force);
  }
  Eigen::Vector3d Direction(const FreeData& data, const Eigen::VectorXd&,
                            const FreeInterval& interval) const override {
    if (!interval.acc || data.upstream_theta.size() != kAcc) return Eigen::Vector3d::Zero();
    return free::UpperTK(data.upstream_theta.data()) *
           (interval.acc->mean - data.upstream_theta.tail<3>());
  }

 private:
  FreeContext context_;
  std::string name_ = "gyro9";
  std::vector<ParameterInfo> params_;
};

}  // namespace turncal::free_gyro
