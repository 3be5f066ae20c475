// gyro9g: gyro9 with the g-sensitivity, a consumer gyro's bias that moves with the specific force
// (core/models/gyro_free.h).

#include "core/models/gyro_free.h"

namespace turncal {
using Gyro9g = free_gyro::GyroFree<true>;
}

TURNCAL_REGISTER_FREE_MODEL(gyro9g, turncal::Gyro9g)
