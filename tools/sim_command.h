#pragma once
// `turncal sim`: a complete simulated turntable session as a .tcap capture (device start-up
// traffic, the sample stream, pose events) plus a truth file.

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddSimCommand(CLI::App* app);

}  // namespace turncal::tools
