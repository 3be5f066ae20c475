#include "sim/tumble.h"

#include <cmath>

#include "core/frames/rotations.h"
#include "core/modeling/parameter_matrices.h"

namespace turncal::sim {
namespace {

// imu_tk's triad matrices, as the models write them (core/modeling/parameter_matrices.h).
using params::FullTK;
using params::Symmetric;
using params::UpperTK;

Eigen::Vector3d Gaussian3(std::mt19937_64* rng, double sigma) {
  std::normal_distribution<double> n(0.0, sigma);
  return {n(*rng), n(*rng), n(*rng)};
}

TriadStats Stats(const Eigen::Vector3d& truth, double sigma, std::int64_t count,
                 std::mt19937_64* rng) {
  TriadStats s;
  s.count = count;
  s.covariance = sigma * sigma * Eigen::Matrix3d::Identity();
  s.mean = truth + Gaussian3(rng, sigma / std::sqrt(static_cast<double>(count)));
  return s;
}

// A rotation body -> world (NED) whose "up" (world -z) is `up_body` in the body, turned about the
// vertical by `heading`.
Eigen::Matrix3d Orientation(const Eigen::Vector3d& up_body, double heading) {
  const Eigen::Matrix3d Q =
      Eigen::Quaterniond::FromTwoVectors(up_body, Eigen::Vector3d(0, 0, -1)).toRotationMatrix();
  return Eigen::AngleAxisd(heading, Eigen::Vector3d::UnitZ()).toRotationMatrix() * Q;
}

}  // namespace

std::vector<FreeInterval> SimulateTumble(const TumbleTruth& truth, const TumbleOptions& options,
                                         std::mt19937_64* rng) {
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const double cos_cap = std::cos(options.cap_deg * M_PI / 180);
  const double lat = options.latitude_deg * M_PI / 180;
  const Eigen::Vector3d earth_w =
      kEarthRate_radps * Eigen::Vector3d(std::cos(lat), 0, -std::sin(lat));
  const Eigen::Vector3d force_w(0, 0, -options.gravity_mps2);
  const Eigen::Vector3d field_w =
      truth.field * Eigen::Vector3d(std::cos(truth.dip_rad), 0, std::sin(truth.dip_rad));
  const Eigen::Matrix3d Ca_inv = UpperTK(truth.accel9.data()).inverse();
  const Eigen::Matrix3d Cg_inv = FullTK(truth.gyro9.data()).inverse();
  const Eigen::Vector3d ba = truth.accel9.tail<3>(), bg = truth.gyro9.tail<3>();
  const Eigen::Matrix3d Sm_inv = Symmetric(truth.mag.data() + 3).inverse();
  const Eigen::Vector3d bm = truth.mag.head<3>();
  const Eigen::Matrix3d R_ma =
      truth.mag_to_acc_rad.norm() > 0
          ? Eigen::AngleAxisd(truth.mag_to_acc_rad.norm(), truth.mag_to_acc_rad.normalized())
                .toRotationMatrix()
          : Eigen::Matrix3d::Identity();
  const auto count = static_cast<std::int64_t>(std::llround(options.still_s * options.rate_hz));
  const double dt = 1.0 / options.rate_hz;

  std::vector<FreeInterval> out;
  Eigen::Matrix3d R_prev;
  double t = 0;
  for (int k = 0; k < options.orientations; ++k) {
    // "Up" in the body: uniform on the sphere, or on the cap about +z.
    const double z = cos_cap + (1 - cos_cap) * uniform(*rng);
    const double az = 2 * M_PI * uniform(*rng);
    const double rho = std::sqrt(std::max(0.0, 1 - z * z));
    const Eigen::Vector3d up(rho * std::cos(az), rho * std::sin(az), z);
    const Eigen::Matrix3d R = Orientation(up, 2 * M_PI * uniform(*rng));
    FreeInterval iv;
    if (k > 0 && options.with_moves && options.gyr_sigma > 0) {
      // A turn at constant rate about the body axis from the one orientation to the next.
      const Eigen::AngleAxisd turn(R_prev.transpose() * R);
      const double T = options.move_s;
      const Eigen::Vector3d w_b = turn.axis() * turn.angle() / T;
      MoveRecord m;
      const int blocks = static_cast<int>(std::lround(T / options.block_s));
      const double tau = T / blocks;
      for (int j = 0; j < blocks; ++j) {
        const double tm = (j + 0.5) * tau;
        const Eigen::Matrix3d Rt =
            R_prev * Eigen::AngleAxisd(turn.angle() * tm / T, turn.axis()).toRotationMatrix();
        const Eigen::Vector3d raw = Cg_inv * (w_b + Rt.transpose() * earth_w) + bg;
        m.increment_rad.push_back(raw * tau +
                                  Gaussian3(rng, options.gyr_sigma * std::sqrt(dt * tau)));
        m.block_s.push_back(tau);
      }
      m.t_start_s = t;
      m.t_end_s = t + T;
      m.samples = static_cast<std::int64_t>(std::llround(T / dt)) + 1;
      iv.move_in = std::move(m);
      t += T;
    }
    iv.t_start_s = iv.sensor_t_start_s = t;
    iv.t_end_s = iv.sensor_t_end_s = t + options.still_s;
    t += options.still_s;
    if (options.acc_sigma > 0) {
      iv.acc = Stats(Ca_inv * (R.transpose() * force_w) + ba, options.acc_sigma, count, rng);
    }
    if (options.gyr_sigma > 0) {
      iv.gyr = Stats(Cg_inv * (R.transpose() * earth_w) + bg, options.gyr_sigma, count, rng);
    }
    if (options.mag_sigma > 0) {
      iv.mag = Stats(Sm_inv * (R_ma.transpose() * (R.transpose() * field_w)) + bm,
                     options.mag_sigma, count, rng);
    }
    out.push_back(std::move(iv));
    R_prev = R;
  }
  return out;
}

std::vector<TablePose> TumbleTablePoses(int n, double cap_deg, std::mt19937_64* rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double cos_cap = std::cos(cap_deg * M_PI / 180);
  std::vector<TablePose> poses;
  for (int k = 0; k < n; ++k) {
    const double z = cos_cap + (1 - cos_cap) * u(*rng);
    const double az = 2 * M_PI * u(*rng);
    const double rho = std::sqrt(std::max(0.0, 1 - z * z));
    const Eigen::Vector3d down(rho * std::cos(az), rho * std::sin(az), -z);
    poses.push_back(PoseWithDownAlong(down, 2 * M_PI * u(*rng) - M_PI));
  }
  return poses;
}

}  // namespace turncal::sim
