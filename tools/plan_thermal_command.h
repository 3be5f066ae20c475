#pragma once
// `turncal plan-thermal` (issue 36): the chamber-and-table time a calibration over temperature
// needs to pass its gate, along the classic soak procedure and along ramps of the chamber with
// the table cycling the cube, simulated in memory with the real calibrator and gate
// (montecarlo/thermal_plan.h); the plan is the quickest ramp that passed in every run.

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddPlanThermalCommand(CLI::App* app);

}  // namespace turncal::tools
