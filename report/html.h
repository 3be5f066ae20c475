#pragma once
// The calibration report (issue "Calibration report"): one self-contained HTML document for one
// device -- inline CSS and inline SVG, no script, nothing fetched -- from the device's active
// calibrations (daemon/state/persistence.h: calibrations/DEVICE.MODEL.json). Per model: identity,
// time, software, poses, gate verdict with reasons and notes; the parameter table in ppm,
// degrees, mg, mG with 1 sigma and the gate's tolerance; the model's other form (G, K, the
// mag22 gauge); residuals per pose before and after calibration; pose coverage on the sphere;
// sigma as poses were added (the calibrator re-solved with the first k poses); observability
// (rank, condition number, weakest direction by parameter names).
//
// The plots are <svg class="plot" id="residuals-MODEL|coverage-MODEL|convergence-MODEL"> with a
// <title>. Residuals, convergence and observability need the pose measurements: the
// calibration's provenance.records (written by the station since the report exists); a caller
// holding them elsewhere (the pose journal) may put them there before rendering.

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace turncal::report {

struct ReportOptions {
  // Where the calibrations came from (a state directory), shown in the header; may be empty.
  std::string source;
  // When the report was made, shown as given (protocol/ reads no clock); may be empty.
  std::string generated_utc;
  // What turncal wrote into the device (the state directory's device_writes/DEVICE.UTCTIME.json
  // entries, oldest first): a section "Written into the device" when there are any.
  std::vector<nlohmann::json> device_writes;
  // The session's batch as the station last published it (the state directory's batch.json,
  // daemon/state/batch_file.h): the report opens with its summary, slot by slot -- serial,
  // pass or what it waits for, the time each unit took -- when it has more than one unit or a
  // fixture. Null: none.
  nlohmann::json batch;
  // The unit's drift over its calibrations (issue 39 item 3): the rows `turncal registry drift
  // SERIAL --json` prints; each model's section then ends with its drift table
  // (report/drift_section.h). Null: none.
  nlohmann::json drift;
};

// Renders the report of the device all `calibrations` belong to (one per model, any order; the
// report lists them by model name). False with a message, and *html untouched, when the list is
// empty, a document is malformed (protocol::ParseCalibrationDocument), two documents name different
// devices or the same model.
bool RenderReportHtml(const std::vector<nlohmann::json>& calibrations, const ReportOptions& options,
                      std::string* html, std::string* error);

}  // namespace turncal::report
