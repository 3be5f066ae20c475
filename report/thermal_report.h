#pragma once
// The calibration report's section for a calibration over temperature (issue 36; a document
// "kind": "thermal", protocol/thermal_json.h): the range, each parameter at the range's ends and at
// t0 with its 1 sigma, a plot of every temperature-dependent parameter against temperature with
// its 1 sigma band, and the poses' residuals against temperature.

#include <nlohmann/json.hpp>
#include <string>

namespace turncal::report {

// False with a message when the document cannot be read.
bool ThermalSectionHtml(const nlohmann::json& document, std::string* html, std::string* error);

}  // namespace turncal::report
