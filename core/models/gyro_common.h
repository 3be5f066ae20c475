#pragma once
// What gyro12 and gyro21 share (issue 21; docs/models.md "Gyroscope models").
//
// omega_m = G_w omega_q + B_g f_q + b_g, with omega_q the inertial angular rate of the table's
// inner frame q written in q (the table's rate plus the Earth's), f_q the specific force in q and
// G_w = (I+S) T_r^s C_q^r the accelerometer's structure for the gyro triad's own scale factors,
// non-orthogonality and rotation from q (so the angle between the gyro and accelerometer triads is
// that between their C_q^r). Parameter layout: Sx Sy Sz alpha1 alpha2 alpha3 eps_x eps_y eps_z
// bx by bz [Bg_xx Bg_xy ... Bg_zz].

#include <string>
#include <vector>

#include "core/models/accel_common.h"

namespace turncal::gyro {

inline constexpr int kBias = 9;
inline constexpr int kGSens = 12;

// The entries of B_g row by row: Bg_ij is output axis i's response to f along q's axis j.
inline std::vector<std::string> GSensitivityNames() {
  std::vector<std::string> names;
  for (char r : {'x', 'y', 'z'})
    for (char c : {'x', 'y', 'z'}) names.push_back(std::string("Bg_") + r + c);
  return names;
}

inline std::vector<ParameterInfo> Parameters(bool with_g_sensitivity) {
  std::vector<ParameterInfo> p = accel::SensorAndMountingParameters();
  for (const char* b : {"bx", "by", "bz"}) {
    p.push_back({b, ParameterKind::kSensor, ParameterUnit::kAngularRate, 0.0});
  }
  if (with_g_sensitivity) {
    for (const auto& name : GSensitivityNames()) {
      p.push_back({name, ParameterKind::kSensor, ParameterUnit::kGSensitivity, 0.0});
    }
  }
  return p;
}

template <typename T>
Vec3<T> Bias(const T* theta) {
  return Vec3<T>(theta[kBias], theta[kBias + 1], theta[kBias + 2]);
}

template <typename T>
Mat3<T> GSensitivity(const T* theta) {
  Mat3<T> B;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) B(r, c) = theta[kGSens + 3 * r + c];
  return B;
}

// The rate in the case frame r: ((I+S) T_r^s)^-1 (omega_m - b - B_g f_q); in the table frame q
// with C_q^r^T. `f_q` is the specific force in q (zero when unknown or when B_g is absent).
inline Eigen::Vector3d Correct(const double* theta, bool with_g_sensitivity,
                               const Eigen::Vector3d& raw, const Eigen::Vector3d& f_q,
                               const ModelContext& context) {
  Eigen::Vector3d y = raw - Bias(theta);
  if (with_g_sensitivity) y -= GSensitivity(theta) * f_q;
  const Mat3<double> sensor = AccelSensorMatrix(theta + accel::kS, theta + accel::kAlpha);
  const Eigen::Vector3d w_r = sensor.triangularView<Eigen::Lower>().solve(y);
  if (context.accel_output_frame == OutputFrame::kCase) return w_r;
  const double* eps = theta + accel::kEps;
  return C_q_r(eps[0], eps[1], eps[2], context.mounting).transpose() * w_r;
}

// The model definition (core/modeling/model_adapter.h) of gyro12 (without B_g) and gyro21 (with
// it); each model's file names it and registers it.
template <bool kWithGSensitivity>
struct Def {
  static constexpr SensorKind kSensor = SensorKind::kGyroscope;

  static std::vector<ParameterInfo> Parameters(const ModelContext&) {
    return gyro::Parameters(kWithGSensitivity);
  }
  template <typename T>
  static Vec3<T> PredictRate(const T* theta, const Vec3<T>& omega_q, const Vec3<T>& f_q,
                             const ModelContext& context) {
    Vec3<T> y = accel::G(theta, context.mounting) * omega_q + Bias(theta);
    if constexpr (kWithGSensitivity) y += GSensitivity(theta) * f_q;
    return y;
  }
  static Eigen::Vector3d Correct(const double* theta, const Eigen::Vector3d& raw,
                                 const Eigen::Vector3d& f_q, const ModelContext& context) {
    return gyro::Correct(theta, kWithGSensitivity, raw, f_q, context);
  }
  static OutputFrame CorrectedFrame(const ModelContext& c) { return c.accel_output_frame; }
  static bool FromLinear(const Mat3<double>& G, double /*beta*/, const Eigen::Vector3d& b,
                         const ModelContext& context, double* theta, std::string* error) {
    const int n = kWithGSensitivity ? kGSens + 9 : kGSens;
    for (int i = kGSens; i < n; ++i) theta[i] = 0.0;
    return accel::FromLinear(G, b, context, kBias, theta, error);
  }
  // theta^e: G_w row by row, then b_g, then (gyro21) B_g row by row.
  template <typename T>
  static void Extended(const T* theta, const ModelContext& context, std::vector<T>* out) {
    const Mat3<T> G = accel::G(theta, context.mounting);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) out->push_back(G(r, c));
    for (int i = 0; i < 3; ++i) out->push_back(theta[kBias + i]);
    if constexpr (kWithGSensitivity) {
      for (int i = kGSens; i < kGSens + 9; ++i) out->push_back(theta[i]);
    }
  }
};

}  // namespace turncal::gyro
