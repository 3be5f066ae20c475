// An accelerometer and magnetometer session simulated along a list of poses (sim/session_sim.h),
// kept with the models, poses and options that made it: the fixture of the sequencer's and the
// session simulator's tests.
#pragma once

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "sim/session_sim.h"

namespace turncal {

struct SimulatedRun {
  std::unique_ptr<MeasurementModel> accel, mag;
  std::vector<TablePose> poses;
  SessionSimOptions options;
  SimulatedSession sim;
};

// accel13 and mag13 with their default truth, simulated along `poses` with `options`.
inline SimulatedRun SimulateAccelMagSession(std::vector<TablePose> poses,
                                            const SessionSimOptions& options) {
  SimulatedRun r;
  std::string error;
  r.accel = MakeModel("accel13", ModelContext{}, &error);
  r.mag = MakeModel("mag13", ModelContext{}, &error);
  r.poses = std::move(poses);
  r.options = options;
  r.sim = SimulateSession(*r.accel, *r.mag, r.poses, r.options);
  return r;
}

}  // namespace turncal
