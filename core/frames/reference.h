#pragma once
// Reference vectors of the lab (MODELS.md "Reference vectors"). Both are configuration; the
// defaults are the seed's (eq. 3 and eq. 22).

#include <Eigen/Core>
#include <string>

namespace turncal {

// MicroStrain reports acceleration in g; the vendor's definition of g.
inline constexpr double kStandardGravity_mps2 = 9.80665;

struct ReferenceVectors {
  // Gravity in the local level frame, m/s^2 (seed eq. 3).
  Eigen::Vector3d g_ned{-0.0167, 0.0, 9.7782};
  // Earth magnetic field in the local level frame, Gauss (seed eq. 22). Any unit works as long as
  // the magnetometer's G absorbs the ratio to the device's unit.
  Eigen::Vector3d B_ned{0.2523, 0.0217, 0.4004};
  // The lab's geodetic latitude, degrees north: the Earth's rate in NED (EarthRateNed), which a
  // gyroscope at rest measures. 45 unless configured ([reference] latitude_deg); the Earth's 15
  // deg/h split between north and down depends on it.
  double latitude_deg = 45.0;

  // False with a message when a vector is not finite or is (near) zero.
  bool IsValid(std::string* error) const;
};

// The accelerometer's excitation: an accelerometer at rest measures specific force f = -g
// (MODELS.md "Sign of the accelerometer's excitation"). This is the one place the sign lives.
inline Eigen::Vector3d SpecificForceNed(const ReferenceVectors& ref) { return -ref.g_ned; }

// The Earth's sidereal rotation rate, rad/s (WGS 84).
inline constexpr double kEarthRate_radps = 7.292115e-5;

// The Earth's rate in the local level frame NED at the reference's latitude: Omega [cos L, 0,
// -sin L] (the rate vector points north and up). A gyroscope's excitation at rest.
Eigen::Vector3d EarthRateNed(const ReferenceVectors& ref);

}  // namespace turncal
