// gyro12: the gyroscope's scale, non-orthogonality, rotation from the table and bias,
// omega_m = G_w omega_q + b_g (core/models/gyro_common.h; docs/models.md "Gyroscope models").

#include "core/modeling/model_adapter.h"
#include "core/models/gyro_common.h"

namespace turncal {
namespace {

struct Gyro12 : gyro::Def</*kWithGSensitivity=*/false> {
  static constexpr std::string_view kName = "gyro12";
  static constexpr int kNumParams = 12;
};

}  // namespace
}  // namespace turncal

TURNCAL_REGISTER_MODEL(gyro12, turncal::Gyro12)
