// gyro21: gyro12 plus the g-sensitivity matrix B_g (9 entries),
// omega_m = G_w omega_q + B_g f_q + b_g (core/models/gyro_common.h; docs/models.md "Gyroscope
// models").

#include "core/modeling/model_adapter.h"
#include "core/models/gyro_common.h"

namespace turncal {
namespace {

struct Gyro21 : gyro::Def</*kWithGSensitivity=*/true> {
  static constexpr std::string_view kName = "gyro21";
  static constexpr int kNumParams = 21;
};

}  // namespace
}  // namespace turncal

TURNCAL_REGISTER_MODEL(gyro21, turncal::Gyro21)
