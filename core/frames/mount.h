#pragma once
// A unit's nominal mount on a fixture (issue 38): the rotation M from the table's inner frame q to
// the unit's case frame r (C_q^r = C(eps) M, MODELS.md "Nominal mounting"), written the two ways
// a fixture's drawing gives it.
//
//   axes   "-y+x+z": the case's x, y and z axes along the table's -y, +x and +z ("+x+y+z" is the
//          identity; the 24 axis-aligned mounts, the faces of a cube and 90-degree steps). Row i
//          of M is case axis i written in q. A left-handed triple is refused.
//   angles [x, y, z] in degrees: M = R1(x) R2(y) R3(z), the project's convention for the small
//          mounting error eps (core/frames/rotations.h), for a fixture whose slots are not
//          axis-aligned (a 45-degree wedge).
//
// And the other way: a rotation's name in the axes form when it is axis-aligned, and what a
// rotation between the configured and the observed mount is in words ("rotated 90 deg about its
// z", "upside down (rotated 180 deg about its x)"). Pure computation.

#include <optional>
#include <string>
#include <string_view>

#include "core/frames/rotations.h"

namespace turncal {

// "-y+x+z" -> M. False with a message when the text is not three signed axes of a right-handed
// triple.
bool ParseMountAxes(std::string_view text, Mat3<double>* mount, std::string* error);

// A mount on a command line: the axes form, or "X,Y,Z" (degrees, the angles form). False with a
// message otherwise.
bool ParseMountText(std::string_view text, Mat3<double>* mount, std::string* error);

// R1(x) R2(y) R3(z), angles in degrees.
Mat3<double> MountFromAnglesDeg(double x_deg, double y_deg, double z_deg);

// The axes form of an axis-aligned rotation (each entry within 1e-6 of 0 or +-1); nullopt
// otherwise.
std::optional<std::string> MountAxesName(const Mat3<double>& mount);

// The angles [x, y, z] in degrees with R1(x) R2(y) R3(z) = mount (y in [-90, 90]).
Eigen::Vector3d MountAnglesDeg(const Mat3<double>& mount);

// How to write `mount` in a configuration: its axes form ("\"-y+x+z\"") when axis-aligned, else
// its angles ("[10.000, 0.000, 45.000]").
std::string MountConfigText(const Mat3<double>& mount);

// A frame rotation D (configured case -> observed case) as an angle and an axis in the configured
// case frame.
struct MountRotation {
  double angle_deg = 0.0;
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  // unit; meaningless at angle 0
};
MountRotation RotationOf(const Mat3<double>& d);

// D in words, for an operator: "rotated 90 deg about its z", "rotated 180 deg about its x (upside
// down)", "rotated 120 deg about its (+x+y+z)". The axis is named when it lies along a case axis or
// a diagonal (within 2 deg), else given as a unit vector.
std::string DescribeMountRotation(const Mat3<double>& d);

}  // namespace turncal
