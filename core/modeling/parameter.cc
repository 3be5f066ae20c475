#include "core/modeling/parameter.h"

#include <fmt/format.h>

#include <cmath>

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
    case ParameterUnit::kAngularRate:
      return "rad/s";
    case ParameterUnit::kGSensitivity:
      return "rad/s/(m/s^2)";
    case ParameterUnit::kSecondOrder:
      return "1/(m/s^2)";
  }
  return "?";
}

DisplayQuantity ForDisplay(const ParameterInfo& p, double v, bool is_sigma) {
  switch (p.unit) {
    case ParameterUnit::kScaleFactor:
      return {v * 1e6, "ppm"};
    case ParameterUnit::kAngle: {
      const bool offset = p.name == "alpha3" && !is_sigma;
      return {(offset ? v - M_PI / 2 : v) * 180 / M_PI, offset ? "deg-90" : "deg"};
    }
    case ParameterUnit::kAcceleration:
      return {v / 9.80665 * 1e3, "mg"};
    case ParameterUnit::kField:
      return {v * 1e3, "mG"};
    case ParameterUnit::kGain:
      return {v, ""};
    case ParameterUnit::kAngularRate:
      return {v * 180 / M_PI * 3600, "deg/h"};
    case ParameterUnit::kGSensitivity:
      return {v * 180 / M_PI * 3600 * 9.80665, "deg/h/g"};
    case ParameterUnit::kSecondOrder:  // K2 a^2 at a = 1 g, in ug
      return {v * 9.80665 * 1e6, "ug/g^2"};
  }
  return {v, ""};
}

std::string FormatSigma(const ParameterInfo& parameter, double sigma) {
  if (!std::isfinite(sigma)) return "inf";
  const DisplayQuantity q = ForDisplay(parameter, sigma, /*is_sigma=*/true);
  return *q.unit ? fmt::format("{:.3g} {}", q.value, q.unit) : fmt::format("{:.3g}", q.value);
}

}  // namespace turncal
