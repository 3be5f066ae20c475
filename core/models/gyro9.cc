// gyro9: a gyroscope without known poses, its gains, misalignment to the accelerometer and bias
// (core/models/gyro_free.h, which also holds gyro9g).

#include "core/models/gyro_free.h"

namespace turncal {
using Gyro9 = free_gyro::GyroFree<false>;
}

TURNCAL_REGISTER_FREE_MODEL(gyro9, turncal::Gyro9)
