#pragma once
// The linear form of MODELS.md (seed eq. 6-10) used to start the nonlinear solver:
// y = H' m' + b with H' = [G cos(beta) | G sin(beta) | G] and the known regressor
// m' = [vx c1 + vy c2 ; vy c1 - vx c2 ; vz c3], c_j the columns of C_p^q.

#include <string>
#include <vector>

#include "core/frames/rotations.h"
#include "core/frames/table_pose.h"

namespace turncal {

struct LinearStart {
  Eigen::Matrix<double, 3, 9> H_prime = Eigen::Matrix<double, 3, 9>::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  Mat3<double> G = Mat3<double>::Identity();  // the third block of H'
  double beta = 0.0;                          // atan2(<block2, G>, <block1, G>)
  int regressor_rank = 0;                     // of the N x 10 stacked [m'^T 1]
  double regressor_min_singular = 0.0;        // smallest singular value, columns scaled to 1
};

// The 9-vector m' for one pose and reference vector v (NED).
Eigen::Matrix<double, 9, 1> LinearRegressor(const TablePose& pose, const Eigen::Vector3d& v_ned);

// Least squares over the poses. False with a message when there are fewer than 10 poses or the
// regressor (with the bias column) has rank below 10: the poses are not diverse enough.
bool SolveLinearStart(const std::vector<TablePose>& poses,
                      const std::vector<Eigen::Vector3d>& measured, const Eigen::Vector3d& v_ned,
                      LinearStart* out, std::string* error);

}  // namespace turncal
