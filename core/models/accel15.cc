// accel15: accel12 with the second-order coefficient K2 of each axis (IEEE Std 1293's model,
// K2 a_i^2 on the specific force along the axis; issue 39 item 4):
//   u = (I+S) T_r^s C_q^r C_p^q f_NED,   a_m = u + K2 (.) u (.) u + b
// (element-wise). A pose with an axis along gravity gives b + u + K2 g^2 on it, one with the axis
// horizontal b: the cube's poses carry K2 (MODELS.md "The second-order term"); the observability
// analysis and the gate say whether a given set does. The heading is taken as known (beta = 0).

#include <cmath>

#include "core/modeling/model_adapter.h"
#include "core/models/accel_common.h"
#include "core/models/extended.h"

namespace turncal {
namespace {

struct Accel15 {
  static constexpr std::string_view kName = "accel15";
  static constexpr int kNumParams = 15;
  static constexpr SensorKind kSensor = SensorKind::kAccelerometer;
  // The bias last, as in every accelerometer model (the simulator and the drift's bias window
  // take the last three).
  static constexpr int kK2 = 9;
  static constexpr int kBias = 12;

  static std::vector<ParameterInfo> Parameters(const ModelContext&) {
    std::vector<ParameterInfo> p = accel::SensorAndMountingParameters();
    for (const char* k : {"K2x", "K2y", "K2z"}) {
      p.push_back({k, ParameterKind::kSensor, ParameterUnit::kSecondOrder, 0.0});
    }
    for (const char* b : {"bx", "by", "bz"}) {
      p.push_back({b, ParameterKind::kSensor, ParameterUnit::kAcceleration, 0.0});
    }
    return p;
  }
  template <typename T>
  static Vec3<T> Predict(const T* theta, const Mat3<T>& C_p_q, const Vec3<T>& f_ned,
                         const ModelContext& context) {
    const Vec3<T> u = accel::G(theta, context.mounting) * (C_p_q * f_ned);
    Vec3<T> a;
    for (int i = 0; i < 3; ++i) a[i] = u[i] + theta[kK2 + i] * u[i] * u[i] + theta[kBias + i];
    return a;
  }
  // u from a_m - b = u + K2 u^2 on each axis (the root near u, in the form that does not cancel),
  // then accel12's correction of u.
  static Eigen::Vector3d Correct(const double* theta, const Eigen::Vector3d& raw,
                                 const ModelContext& context) {
    Eigen::Vector3d linear = raw;
    for (int i = 0; i < 3; ++i) {
      const double y = raw[i] - theta[kBias + i], k2 = theta[kK2 + i];
      const double disc = 1.0 + 4.0 * k2 * y;
      const double u = disc > 0 ? 2.0 * y / (1.0 + std::sqrt(disc)) : y;
      linear[i] = u + theta[kBias + i];
    }
    return accel::Correct(theta, kBias, linear, context);
  }
  static OutputFrame CorrectedFrame(const ModelContext& c) { return c.accel_output_frame; }
  static bool FromLinear(const Mat3<double>& G, double /*beta*/, const Eigen::Vector3d& b,
                         const ModelContext& context, double* theta, std::string* error) {
    theta[kK2] = theta[kK2 + 1] = theta[kK2 + 2] = 0.0;
    return accel::FromLinear(G, b, context, kBias, theta, error);
  }
  template <typename T>
  static void Extended(const T* theta, const ModelContext& context, std::vector<T>* out) {
    extended::AppendHPrime(accel::G(theta, context.mounting), T(0.0), out);
    extended::AppendVector(Vec3<T>(theta[kBias], theta[kBias + 1], theta[kBias + 2]), out);
    extended::AppendVector(Vec3<T>(theta[kK2], theta[kK2 + 1], theta[kK2 + 2]), out);
  }
};

}  // namespace
}  // namespace turncal

TURNCAL_REGISTER_MODEL(accel15, turncal::Accel15)
