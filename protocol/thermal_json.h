#pragma once
// A calibration over temperature (issue 36; core/estimation/thermal_calibrator.h) as JSON: the
// estimate's section ("temperature": the reference t0, the calibrated range, each parameter's
// order and why, the coefficients with their sigma and covariance, each parameter with its sigma
// at t0 and at the range's ends) and the station's document calibrations/DEVICE.MODEL@T.json
// (docs/THERMAL.md "The document").

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/analysis/publish_gate.h"
#include "core/estimation/calibrator.h"
#include "core/estimation/pose_record.h"
#include "core/estimation/thermal_calibrator.h"
#include "core/modeling/measurement_model.h"

namespace turncal::protocol {

// The estimate's section.
nlohmann::json ToJson(const ThermalEstimate& estimate);

// Each parameter at `temp_c`: {name: {value, sigma}}.
nlohmann::json ParamsAtJson(const ThermalEstimate& estimate, double temp_c);

struct ThermalCalibrationInput {
  std::string device;
  std::string name;  // "accel13@T"
  int version = 0;
  const MeasurementModel* model = nullptr;    // required: the isothermal model (accel13)
  const ThermalEstimate* estimate = nullptr;  // required
  GateResult gate;
  GateOptions gate_options;
  CalibratorOptions calibrator;
  std::string sensor_class;
  ModelContext context;
  const std::vector<PoseRecord>* records = nullptr;  // required: the records fitted
  nlohmann::json identity;
};
// The document (schema 1, "kind": "thermal"), with "software" set; the caller adds "time".
nlohmann::json ThermalCalibrationJson(const ThermalCalibrationInput& input);

// Whether a calibration document is one over temperature.
bool IsThermalCalibration(const nlohmann::json& document);

// The polynomials a station applies from a document's "temperature" section: the basis, the
// coefficients, their covariance and the range, for `model`'s parameters. False with a reason when
// the section is missing or malformed, or does not fit the model.
bool ReadThermalEstimate(const MeasurementModel& model, const nlohmann::json& document,
                         ThermalEstimate* out, std::string* why);

}  // namespace turncal::protocol
