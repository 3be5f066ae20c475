#pragma once
// turncal noise FILE: the overlapping Allan deviation of a static recording per triad and axis,
// with the fitted noise model (core/analysis/allan.h) as a table, JSON or a log-log SVG plot --
// what allan_variance_ros and imu_utils give their users, for the noise profile a station is
// configured with.

#include <CLI/CLI.hpp>

namespace turncal::tools {
void AddNoiseCommand(CLI::App* app);
}
