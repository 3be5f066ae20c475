#pragma once
// What accel12 and accel13 share: parameter table, sensor matrix, correction and linear start.
// Parameter layout: Sx Sy Sz alpha1 alpha2 alpha3 eps_x eps_y eps_z [beta] bx by bz.

#include <cmath>
#include <string>
#include <vector>

#include "core/modeling/accel_physical.h"
#include "core/modeling/measurement_model.h"

namespace turncal::accel {

inline constexpr int kS = 0, kAlpha = 3, kEps = 6;

// Sx Sy Sz alpha1 alpha2 alpha3 eps_x eps_y eps_z: the physical parameters of (I+S) T_r^s C_q^r.
inline std::vector<ParameterInfo> SensorAndMountingParameters() {
  const auto S = ParameterKind::kSensor;
  const auto M = ParameterKind::kMounting;
  return {
      {"Sx", S, ParameterUnit::kScaleFactor, 0.0}, {"Sy", S, ParameterUnit::kScaleFactor, 0.0},
      {"Sz", S, ParameterUnit::kScaleFactor, 0.0}, {"alpha1", S, ParameterUnit::kAngle, 0.0},
      {"alpha2", S, ParameterUnit::kAngle, 0.0},   {"alpha3", S, ParameterUnit::kAngle, M_PI / 2},
      {"eps_x", M, ParameterUnit::kAngle, 0.0},    {"eps_y", M, ParameterUnit::kAngle, 0.0},
      {"eps_z", M, ParameterUnit::kAngle, 0.0},
  };
}

inline std::vector<ParameterInfo> Parameters(bool with_beta) {
  std::vector<ParameterInfo> p = SensorAndMountingParameters();
  if (with_beta) p.push_back({"beta", ParameterKind::kInstallation, ParameterUnit::kAngle, 0.0});
  for (const char* b : {"bx", "by", "bz"}) {
    p.push_back({b, ParameterKind::kSensor, ParameterUnit::kAcceleration, 0.0});
  }
  return p;
}

// G = (I+S) T_r^s C_q^r.
template <typename T>
Mat3<T> G(const T* theta, const Mat3<double>& mounting) {
  return AccelSensorMatrix(theta + kS, theta + kAlpha) *
         C_q_r(theta[kEps], theta[kEps + 1], theta[kEps + 2], mounting);
}

// a_r = ((I+S) T_r^s)^-1 (a_m - b); in the table frame q: C_q^r^T a_r.
inline Eigen::Vector3d Correct(const double* theta, int bias_index, const Eigen::Vector3d& raw,
                               const ModelContext& context) {
  const Eigen::Vector3d b(theta[bias_index], theta[bias_index + 1], theta[bias_index + 2]);
  const Mat3<double> sensor = AccelSensorMatrix(theta + kS, theta + kAlpha);
  const Eigen::Vector3d a_r = sensor.triangularView<Eigen::Lower>().solve(raw - b);
  if (context.accel_output_frame == OutputFrame::kCase) return a_r;
  return C_q_r(theta[kEps], theta[kEps + 1], theta[kEps + 2], context.mounting).transpose() * a_r;
}

inline bool FromLinear(const Mat3<double>& G, const Eigen::Vector3d& b, const ModelContext& context,
                       int bias_index, double* theta, std::string* error) {
  AccelPhysical p;
  if (!AccelPhysicalFromG(G, context.mounting, &p, error)) return false;
  for (int i = 0; i < 3; ++i) {
    theta[kS + i] = p.S[i];
    theta[kAlpha + i] = p.alpha[i];
    theta[kEps + i] = p.eps[i];
    theta[bias_index + i] = b[i];
  }
  return true;
}

}  // namespace turncal::accel
