#pragma once
// turncal free FILE [FILE2]: a calibration without a turntable (issue 22, free mode) on recorded
// files -- a .tcap capture, a raw device stream, a text or CSV log, or imu_tk's pair of .mat text
// files: the static intervals found by the sequencer in free mode, then each free model
// (core/modeling/free_model.h: accel9, gyro9, gyro9g, magellipsoid, magsphere, accmag) with its 1
// sigma, fit check, rank and weak directions, spatial coverage, gate, the next orientation to
// add, and the misfits before and after the calibration.

#include <CLI/CLI.hpp>

namespace turncal::tools {
void AddFreeCommand(CLI::App* app);
}
