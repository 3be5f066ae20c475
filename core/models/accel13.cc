// accel13: the seed's accelerometer model (eq. 1-2, with f = -g),
// a_m = (I+S) T_r^s C_q^r C_p^q C_NED^p f_NED + b, beta the table's heading offset.

#include "core/modeling/model_adapter.h"
#include "core/models/accel_common.h"
#include "core/models/extended.h"

namespace turncal {
namespace {

struct Accel13 {
  static constexpr std::string_view kName = "accel13";
  static constexpr int kNumParams = 13;
  static constexpr SensorKind kSensor = SensorKind::kAccelerometer;
  static constexpr int kBeta = 9;
  static constexpr int kBias = 10;

  static std::vector<ParameterInfo> Parameters(const ModelContext&) {
    return accel::Parameters(/*with_beta=*/true);
  }
  template <typename T>
  static Vec3<T> Predict(const T* theta, const Mat3<T>& C_p_q, const Vec3<T>& f_ned,
                         const ModelContext& context) {
    return accel::G(theta, context.mounting) * (C_p_q * (C_ned_p(theta[kBeta]) * f_ned)) +
           Vec3<T>(theta[kBias], theta[kBias + 1], theta[kBias + 2]);
  }
  static Eigen::Vector3d Correct(const double* theta, const Eigen::Vector3d& raw,
                                 const ModelContext& context) {
    return accel::Correct(theta, kBias, raw, context);
  }
  static OutputFrame CorrectedFrame(const ModelContext& c) { return c.accel_output_frame; }
  static bool FromLinear(const Mat3<double>& G, double beta, const Eigen::Vector3d& b,
                         const ModelContext& context, double* theta, std::string* error) {
    theta[kBeta] = beta;
    return accel::FromLinear(G, b, context, kBias, theta, error);
  }
  template <typename T>
  static void Extended(const T* theta, const ModelContext& context, std::vector<T>* out) {
    extended::AppendHPrime(accel::G(theta, context.mounting), theta[kBeta], out);
    extended::AppendVector(Vec3<T>(theta[kBias], theta[kBias + 1], theta[kBias + 2]), out);
  }
};

}  // namespace
}  // namespace turncal

TURNCAL_REGISTER_MODEL(accel13, turncal::Accel13)
