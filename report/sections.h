#pragma once
// The calibration report's HTML sections for one model (report/html.h assembles them):
// the gate's verdict, the parameter table in the units an engineer reads, the model's other
// form (G for the accelerometers; G and K for the magnetometers), the residual summary and the
// observability summary. All text is escaped.

#include <string>

#include "protocol/calibration_json.h"
#include "report/analysis.h"

namespace turncal::report {

std::string GateHtml(const protocol::CalibrationDocument& doc);
// One row per parameter, <tr id="param-MODEL-NAME" data-value=... data-sigma=...> with the
// stored value and sigma at full precision (SI units) beside the displayed ones.
std::string ParameterTableHtml(const protocol::CalibrationDocument& doc);
std::string PhysicalFormHtml(const protocol::CalibrationDocument& doc);
std::string ResidualSummaryHtml(const protocol::CalibrationDocument& doc,
                                const ModelAnalysis& analysis);
// A gyroscope's parameters by source: 1 sigma from the static poses alone, from the rate
// segments alone, and from both (ModelAnalysis::sources).
std::string SourcesHtml(const protocol::CalibrationDocument& doc, const ModelAnalysis& analysis);
// A gyroscope's scale against the rate: the rate segments' apparent scale error per |rate|, the
// slope, the chi^2 test and the asymmetry of the two signs (core/analysis/rate_linearity.h).
std::string RateLinearityHtml(const protocol::CalibrationDocument& doc,
                              const ModelAnalysis& analysis);
std::string ObservabilityHtml(const protocol::CalibrationDocument& doc,
                              const ModelAnalysis& analysis);

}  // namespace turncal::report
