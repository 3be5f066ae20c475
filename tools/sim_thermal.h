#pragma once
// `turncal sim --chamber`: the chamber's options into the session, and the truth over temperature
// (issue 36; docs/THERMAL.md "Simulated sessions").

#include <nlohmann/json.hpp>
#include <string>

#include "sim/capture.h"
#include "tools/sim_options.h"

namespace turncal::tools {

// The chamber, the die and the poses' repetition from the command line (nothing without
// --chamber). False with a message when the profile does not parse or a value is out of range.
bool ApplyChamberArgs(const SimCommandArgs& args, SessionSimOptions* session, std::string* error);

// The truth file's "thermal" section (null without a chamber): each model's polynomials (t0,
// orders, coefficients per degC^j: what a calibration over temperature estimates, the biases'
// plus the wander over the latest pose's window), and per pose the die's mean temperature and
// the biases' wander in 1-second slices of session time (a harness averages the slices inside
// any bias_window a calibration reports).
nlohmann::json ThermalTruthJson(const sim::SimCapture& capture);

}  // namespace turncal::tools
