#pragma once
// The publish gate over temperature (issue 36): a calibration over temperature is published only
// when every gated parameter's sigma at every temperature of the calibrated range [T_min, T_max]
// is within its tolerance (the gate names the temperatures where it is not), the records span
// enough of a range to call it one, every coefficient is determined, chi^2 agrees with the noise,
// and no pose is extreme. The same tolerances and fit limits as the isothermal gate
// (core/analysis/publish_gate.h).

#include "core/analysis/publish_gate.h"
#include "core/estimation/thermal_calibrator.h"

namespace turncal {

struct ThermalGateOptions {
  // The calibrated range must span at least this much (ArduPilot's thermal calibration asks for
  // 10 degC): a narrower one is an isothermal calibration that would clamp everywhere else.
  double min_span_c = 10.0;
  // The range is checked at this many evenly spaced temperatures, its ends included.
  int grid_points = 41;

  bool IsValid(std::string* error) const;
};

// The gate on a calibration over temperature of `model`.
GateResult EvaluateThermalGate(const MeasurementModel& model, const ThermalEstimate& estimate,
                               const GateOptions& options, const ThermalGateOptions& thermal);

// The worst sigma of each gated parameter over the range and where it is (the ESTIMATE event's
// precision bars): name -> {sigma, tolerance, at_c}.
struct ThermalPrecision {
  std::string name;
  double sigma = 0.0;  // the largest over the range
  double at_c = 0.0;   // where
  double tolerance = 0.0;
};
std::vector<ThermalPrecision> WorstPrecisionOverRange(const MeasurementModel& model,
                                                      const ThermalEstimate& estimate,
                                                      const GateOptions& options, int grid_points);

}  // namespace turncal
