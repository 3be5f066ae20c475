#include "core/parameter.h"

namespace turncal {

const char* ToString(ParameterKind kind) {
  switch (kind) {
    case ParameterKind::kSensor:
      return "sensor";
    case ParameterKind::kMounting:
      return "mounting";
    case ParameterKind::kInstallation:
      return "installation";
  }
  return "?";
}

const char* ToString(ParameterUnit unit) {
  switch (unit) {
    case ParameterUnit::kScaleFactor:
      return "1";
    case ParameterUnit::kAngle:
      return "rad";
    case ParameterUnit::kAcceleration:
      return "m/s^2";
    case ParameterUnit::kField:
      return "field";
    case ParameterUnit::kGain:
      return "1";
  }
  return "?";
}

}  // namespace turncal
