#pragma once
// A calibration over temperature (issue 36; core/estimation/thermal_calibrator.h) as JSON: the
// estimate's section ("temperature": the reference t0, the calibrated range, each parameter's
// order and why, the coefficients with their sigma and covariance, each parameter with its sigma
// at t0 and at the range's ends) and the station's document calibrations/DEVICE.MODEL@T.json
// (docs/THERMAL.md "The document").

#include <map>
#include <memory>
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

// A station's document over temperature, parsed and checked against its base model (what a
// certificate states).
struct ThermalCalibrationDocument {
  std::string device;
  std::string model;       // "accel13@T"
  std::string base_model;  // "accel13"
  int version = 0;
  std::string software;
  std::string time;
  std::string sensor_class;  // "" when not recorded
  ModelContext context;
  bool context_recorded = false;
  std::unique_ptr<MeasurementModel> measurement_model;  // the base model, with `context`
  ThermalEstimate estimate;
  // The coefficients' covariance is in the document, whole and finite: sigma at any temperature
  // follows. Otherwise only each coefficient's own sigma is known (sigma at t0).
  bool covariance_complete = false;
  double chi2 = 0.0, p_value = 1.0;
  int dof = 0, rank = 0;
  std::map<std::string, double> tolerances;  // recorded, else the class's (industrial's)
  bool tolerances_recorded = false;
};
// False with a message naming what is wrong when the document is not a calibration over
// temperature of a known model with a polynomial for each of its parameters.
bool ParseThermalCalibrationDocument(const nlohmann::json& j, ThermalCalibrationDocument* out,
                                     std::string* error);

}  // namespace turncal::protocol
