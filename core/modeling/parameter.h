#pragma once
// Description of one model parameter: its name (exactly as MODELS.md writes it), nominal value,
// physical unit, and whether it describes the sensor or its installation on the table.

#include <string>
#include <vector>

namespace turncal {

// Sensor parameters enter the correction of live samples; installation parameters describe the
// table (MODELS.md "What the publish gate protects"). Mounting angles (eps) are installation
// parameters when output is wanted in the case frame and sensor parameters when it is wanted in
// the table frame.
enum class ParameterKind { kSensor, kMounting, kInstallation };

enum class ParameterUnit {
  kScaleFactor,   // dimensionless relative error; reports use ppm
  kAngle,         // rad; reports add degrees
  kAcceleration,  // m/s^2; reports use mg
  kField,         // the magnetometer's unit (Gauss for MicroStrain, arbitrary for Xsens)
  kGain,          // dimensionless matrix entry (G, K)
  kAngularRate,   // rad/s; reports use deg/h
  kGSensitivity,  // rad/s per m/s^2 (a gyroscope's response to specific force); reports deg/h/g
  kSecondOrder,   // per m/s^2: an accelerometer's K2 (output error K2 a^2); reports ug/g^2
};

struct ParameterInfo {
  std::string name;
  ParameterKind kind = ParameterKind::kSensor;
  ParameterUnit unit = ParameterUnit::kGain;
  double nominal = 0.0;
};

const char* ToString(ParameterKind kind);
const char* ToString(ParameterUnit unit);

// A value in the unit a test engineer reads: ppm for scale factors, degrees for angles (alpha3
// as its deviation from 90 degrees), mg for accelerations, mG for fields (the magnetometer's unit
// taken as Gauss), deg/h for angular rates and deg/h/g for g-sensitivity. Sigmas are shown without
// alpha3's offset.
struct DisplayQuantity {
  double value = 0.0;
  const char* unit = "";
};
DisplayQuantity ForDisplay(const ParameterInfo& parameter, double value, bool is_sigma);
// "230 ppm", "0.012 deg", "1.5 mg"; "inf" for an undetermined sigma.
std::string FormatSigma(const ParameterInfo& parameter, double sigma);

}  // namespace turncal
