#pragma once
// The report of a calibration without a turntable (issue 22, `turncal free`): the intervals
// found, and per free model its parameters with 1 sigma, the fit check, the rank and weakest
// direction, the misfits before and after, the spatial coverage (MicroStrain's 18 x 32 bins) with
// a coverage sphere, the gate and the next orientation to add -- as text, JSON and HTML.

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/analysis/free_advice.h"
#include "core/estimation/free_calibrator.h"
#include "core/estimation/free_motion.h"
#include "core/sequencing/free_intervals.h"

namespace turncal::report {

struct FreeReportInput {
  std::string title = "Calibration without a turntable";
  std::string source;  // where the samples came from, one line
  // Lines under the source (a station's calibrations: each model's version and provenance).
  std::vector<std::string> lines;
  FreeIntervals found;
  // The magnetometer's samples in motion taken as data (issue 37), when any were looked for.
  std::optional<MotionPoints> motion;
  FreeContext context;
  std::vector<FreeModelResult> results;
  std::vector<std::optional<OrientationAdvice>> advice;  // per result
};

// `list_intervals`: a line per interval.
std::string FreeReportText(const FreeReportInput& input, bool list_intervals);
nlohmann::json FreeReportJson(const FreeReportInput& input);
std::string FreeReportHtml(const FreeReportInput& input);
// The same without the page around it: a section per model (for a report that also holds
// calibrations made on a turntable).
std::string FreeReportBody(const FreeReportInput& input);

// The report of a station's free calibration documents (protocol/free_json.h, one per model of one
// device): each re-fitted from the intervals it holds with the context and gate it records, and
// the re-fit checked against the stored values (a line says by how many sigma they differ).
// False with a message when a document does not parse or cannot be re-fitted.
bool FreeCalibrationsReport(const std::vector<nlohmann::json>& calibrations,
                            const std::string& source, FreeReportInput* out, std::string* error);
// The coverage sphere: the 18 x 32 bins as a latitude-longitude map and the directions seen from
// above (+z) and below, as inline SVG.
std::string CoverageSphereSvg(const FreeEstimate& estimate, const std::string& id);

}  // namespace turncal::report
