#pragma once
// `turncal plan-vs-cube`: simulated sessions that run the real calibrator and publish gate after
// every pose, once along the plain 26-pose cube sequence and once with next-pose planning, and
// count the poses each needs to pass the gate.

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddPlanCompareCommand(CLI::App* app);

}  // namespace turncal::tools
