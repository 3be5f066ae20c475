#pragma once
// A device turned by hand (issue 37): a continuous, smooth rotation with no known pose, as a
// field calibration of a magnetometer takes it (ArduPilot's compass calibration, MicroStrain's
// magnetometer tool, MotionCal). The path is the three table angles (phi, gamma, psi) as smooth
// functions of a motion time u, so the session simulator turns it into samples exactly as it
// does a table's moves (sim/session_sim.h); the real time t runs u through pauses, where the hand
// slows to a stop, holds still and starts again (a smooth ramp each way, no step in the rate).
//
//   tumble:   phi and psi turn on (at random rates and senses) with slow wobbles, gamma swings
//             across +-75 deg: the device's axes visit every direction;
//   figure8:  phi and psi swing as a figure of eight (psi at twice phi's frequency), gamma
//             wobbles: what the vendors' tools ask of a hand;
//   planar:   psi only, at a constant rate (a vehicle driven in a circle): the field turns about
//             one axis, and only what that turn shows can be determined.
//
// The motion's body rate has the RMS `rate_dps` over the path (30-180 deg/s for a hand). The
// path's random draws come from a stream of their own (the seed's), so the session's noise
// stream is unchanged. Pure computation.

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

namespace turncal::sim {

struct HandMotion {
  enum class Path { kTumble, kFigureEight, kPlanar };
  Path path = Path::kTumble;
  double duration_s = 10.0;  // of the motion, pauses included
  double rate_dps = 90.0;    // RMS of the body rate while moving
  // A pause of pause_s after every pause_every_s of motion (0: none); ramp_s to stop and to
  // start again, within the pause.
  double pause_every_s = 0.0;
  double pause_s = 1.0;
  double ramp_s = 0.3;

  bool IsValid(std::string* error) const;
};

// "tumble", "figure8", "planar"; false for another name.
bool HandPathByName(const std::string& name, HandMotion::Path* path);
const char* HandPathName(HandMotion::Path path);

class HandPath {
 public:
  HandPath(const HandMotion& motion, std::uint64_t seed);

  // The table angles (phi, gamma, psi), rad, and their rates, rad/s, `since` seconds after the
  // motion started (held at the last angles after its end).
  void At(double since, Eigen::Vector3d* angles, Eigen::Vector3d* rates) const;
  // The fraction of full speed at `since` (0 in a pause, 1 in motion).
  double Speed(double since) const;
  const HandMotion& motion() const { return motion_; }

 private:
  // Motion time u at real time `since` (the pauses' and the start's lost time taken off).
  double MotionTime(double since) const;
  void Shape(double u, Eigen::Vector3d* angles, Eigen::Vector3d* rates) const;

  HandMotion motion_;
  double scale_ = 1.0;  // u's frequencies, so that the body rate's RMS is rate_dps
  // Per angle: a constant rate and two sinusoids (amplitude, angular frequency, phase).
  Eigen::Vector3d drift_ = Eigen::Vector3d::Zero();
  double amplitude_[3][2] = {}, omega_[3][2] = {}, phase_[3][2] = {};
};

}  // namespace turncal::sim
