#pragma once
// The drift of a unit with history (issue 39 item 3), as the certificate and the calibration
// report show it: per parameter of one model, the calibrations it rests on, the turn-on
// repeatability with its 95 % interval, the trend per month with sigma and the recalibration date
// with sigma and its 95 % "not before" -- from the rows `turncal registry drift --json` prints
// (tools/registry_drift.cc). Values shown in the parameter's report unit (ppm, deg, mg ...).

#include <nlohmann/json.hpp>
#include <string>

namespace turncal::report {

// The rows of `model` (every row when empty), without their per-calibration "history": what a
// certificate's data block keeps. Null when no row of the model has a trend (two calibrations).
nlohmann::json DriftSummary(const nlohmann::json& rows, const std::string& model);

// <section class="drift"> with one table row per parameter; "" when `summary` is null or empty.
std::string DriftSectionHtml(const nlohmann::json& summary, const std::string& model);

}  // namespace turncal::report
