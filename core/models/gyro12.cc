// gyro12: the gyroscope's scale, non-orthogonality, rotation from the table and bias,
// omega_m = G_w omega_q + b_g (core/models/gyro_common.h; docs/models.md "Gyroscope models").

#include "core/modeling/model_adapter.h"
#include "core/models/extended.h"
#include "core/models/gyro_common.h"

namespace turncal {
namespace {

struct Gyro12 {
  static constexpr std::string_view kName = "gyro12";
  static constexpr int kNumParams = 12;
  static constexpr SensorKind kSensor = SensorKind::kGyroscope;
  static constexpr bool kWithGSensitivity = false;

  static std::vector<ParameterInfo> Parameters(const ModelContext&) {
    return gyro::Parameters(kWithGSensitivity);
  }
  template <typename T>
  static Vec3<T> PredictRate(const T* theta, const Vec3<T>& omega_q, const Vec3<T>& f_q,
                             const ModelContext& context) {
    Vec3<T> y = accel::G(theta, context.mounting) * omega_q + gyro::Bias(theta);
    if constexpr (kWithGSensitivity) y += gyro::GSensitivity(theta) * f_q;
    return y;
  }
  static Eigen::Vector3d Correct(const double* theta, const Eigen::Vector3d& raw,
                                 const Eigen::Vector3d& f_q, const ModelContext& context) {
    return gyro::Correct(theta, kWithGSensitivity, raw, f_q, context);
  }
  static OutputFrame CorrectedFrame(const ModelContext& c) { return c.accel_output_frame; }
  static bool FromLinear(const Mat3<double>& G, double /*beta*/, const Eigen::Vector3d& b,
                         const ModelContext& context, double* theta, std::string* error) {
    for (int i = gyro::kGSens; i < kNumParams; ++i) theta[i] = 0.0;
    return accel::FromLinear(G, b, context, gyro::kBias, theta, error);
  }
  // theta^e: G_w row by row, then b_g.
  template <typename T>
  static void Extended(const T* theta, const ModelContext& context, std::vector<T>* out) {
    const Mat3<T> G = accel::G(theta, context.mounting);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) out->push_back(G(r, c));
    extended::AppendVector(gyro::Bias(theta), out);
    if constexpr (kWithGSensitivity) {
      for (int i = gyro::kGSens; i < kNumParams; ++i) out->push_back(theta[i]);
    }
  }
};

}  // namespace
}  // namespace turncal

TURNCAL_REGISTER_MODEL(gyro12, turncal::Gyro12)
