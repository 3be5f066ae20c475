// accel12: the traditional accelerometer model, a_m = (I+S) T_r^s C_q^r C_p^q f_NED + b
// (MODELS.md; the table's heading is taken as known, beta = 0).

#include "core/modeling/model_adapter.h"
#include "core/models/accel_common.h"
#include "core/models/extended.h"

namespace turncal {
namespace {

struct Accel12 {
  static constexpr std::string_view kName = "accel12";
  static constexpr int kNumParams = 12;
  static constexpr SensorKind kSensor = SensorKind::kAccelerometer;
  static constexpr int kBias = 9;

  static std::vector<ParameterInfo> Parameters(const ModelContext&) {
    return accel::Parameters(/*with_beta=*/false);
  }
  template <typename T>
  static Vec3<T> Predict(const T* theta, const Mat3<T>& C_p_q, const Vec3<T>& f_ned,
                         const ModelContext& context) {
    return accel::G(theta, context.mounting) * (C_p_q * f_ned) +
           Vec3<T>(theta[kBias], theta[kBias + 1], theta[kBias + 2]);
  }
  static Eigen::Vector3d Correct(const double* theta, const Eigen::Vector3d& raw,
                                 const ModelContext& context) {
    return accel::Correct(theta, kBias, raw, context);
  }
  static OutputFrame CorrectedFrame(const ModelContext& c) { return c.accel_output_frame; }
  static bool FromLinear(const Mat3<double>& G, double /*beta*/, const Eigen::Vector3d& b,
                         const ModelContext& context, double* theta, std::string* error) {
    return accel::FromLinear(G, b, context, kBias, theta, error);
  }
  // The traditional model has no beta: H' = [G | 0 | G].
  template <typename T>
  static void Extended(const T* theta, const ModelContext& context, std::vector<T>* out) {
    extended::AppendHPrime(accel::G(theta, context.mounting), T(0.0), out);
    extended::AppendVector(Vec3<T>(theta[kBias], theta[kBias + 1], theta[kBias + 2]), out);
  }
};

}  // namespace
}  // namespace turncal

TURNCAL_REGISTER_MODEL(accel12, turncal::Accel12)
