#pragma once
// A tumble at the level of its static intervals (issue 22): a device placed by hand in N unknown
// orientations, still for a while in each and turned between them, as the free models see it
// (core/modeling/free_model.h). Each interval's triad means carry white noise of the interval's
// length; each move is the gyro's raw increments over 10 ms blocks of a turn at constant rate
// about the axis from one orientation to the next, with the gyro's white noise and the Earth's
// rate in it. The truth is in the free models' own parameters, so Monte Carlo can compare.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <random>
#include <vector>

#include "core/frames/table_pose.h"
#include "core/modeling/free_model.h"

namespace turncal::sim {

struct TumbleTruth {
  // accel9: kx ky kz m_yz m_zy m_zx bx by bz.
  Eigen::VectorXd accel9 =
      (Eigen::VectorXd(9) << 1.004, 0.997, 1.002, 0.002, -0.003, 0.0015, 0.05, -0.08, 0.12)
          .finished();
  // gyro9: kx ky kz m_yz m_zy m_zx m_xz m_xy m_yx bx by bz.
  Eigen::VectorXd gyro9 = (Eigen::VectorXd(12) << 1.01, 0.995, 1.003, 0.003, -0.002, 0.004, -0.001,
                           0.002, -0.003, 0.004, -0.003, 0.002)
                              .finished();
  // magellipsoid: bx by bz s11 s12 s13 s22 s23 s33, field in the unit of `field`.
  Eigen::VectorXd mag =
      (Eigen::VectorXd(9) << 0.08, -0.05, 0.12, 1.05, 0.03, -0.02, 0.96, 0.04, 1.01).finished();
  Eigen::Vector3d mag_to_acc_rad{0.02, -0.015, 0.03};  // the magnetometer's triad to the accel's
  double field = 0.5;                                  // |B|, Gauss
  double dip_rad = 1.05;                               // ~60 degrees
};

struct TumbleOptions {
  int orientations = 30;
  // Orientations uniform on the rotations, or (cap_deg < 180) with "up" within cap_deg of the
  // sensor's +z: a low-coverage tumble.
  double cap_deg = 180.0;
  double still_s = 4.0;
  double move_s = 3.0;
  double rate_hz = 100.0;
  double block_s = 0.01;
  // White noise per sample, triad units; 0 leaves a triad out.
  double acc_sigma = 0.02;   // m/s^2
  double gyr_sigma = 0.005;  // rad/s
  double mag_sigma = 0.002;  // Gauss
  double latitude_deg = 45.0;
  double gravity_mps2 = 9.80665;
  bool with_moves = true;
};

// The orientations of a byte-level tumble on a three-axis table (turncal sim's session, whose pose
// events free mode ignores): "down" uniform on the sphere, or within cap_deg of the table's -z
// ("up" near +z: low coverage), turned about the vertical at random.
std::vector<TablePose> TumbleTablePoses(int n, double cap_deg, std::mt19937_64* rng);

// The intervals of one tumble; `rng` draws orientations and noise.
std::vector<FreeInterval> SimulateTumble(const TumbleTruth& truth, const TumbleOptions& options,
                                         std::mt19937_64* rng);

}  // namespace turncal::sim
