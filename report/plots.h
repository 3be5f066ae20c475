#pragma once
// The calibration report's plots, each one <svg class="plot" id="KIND-MODEL"> with a <title>:
//   residuals-MODEL    residual per pose and axis before calibration (nominal parameters) and
//                      after (the estimate), with each pose mean's 1 sigma
//   coverage-MODEL     where the reference vector pointed in the sensor frame, two hemispheres
//                      in orthographic projection
//   convergence-MODEL  each parameter's sigma as poses were added: gated parameters against
//                      their tolerance, the others against their final sigma (log scales)
// A plot without the data it needs still appears, saying what is missing.

#include <string>

#include "protocol/calibration_json.h"
#include "report/analysis.h"

namespace turncal::report {

// A triad's residual in the unit the report shows: mg for accelerometers, mG for magnetometers
// (the device unit taken as Gauss, as core/modeling/parameter.h's ForDisplay does).
struct ResidualUnit {
  double per_triad_unit = 1.0;  // display value = triad value * per_triad_unit
  const char* name = "";
};
ResidualUnit ResidualUnitFor(const MeasurementModel& model);

std::string ResidualsSvg(const protocol::CalibrationDocument& doc, const ModelAnalysis& analysis);
std::string CoverageSvg(const protocol::CalibrationDocument& doc, const ModelAnalysis& analysis);
std::string ConvergenceSvg(const protocol::CalibrationDocument& doc, const ModelAnalysis& analysis);

}  // namespace turncal::report
