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

  // False with a message when a vector is not finite or is (near) zero.
  bool IsValid(std::string* error) const;
};

// The accelerometer's excitation: an accelerometer at rest measures specific force f = -g
// (MODELS.md "Sign of the accelerometer's excitation"). This is the one place the sign lives.
inline Eigen::Vector3d SpecificForceNed(const ReferenceVectors& ref) { return -ref.g_ned; }

}  // namespace turncal
