#pragma once
// JSON of calibrations without known poses (issue 22: turncald's free pose source, docs/FREE.md
// "In the daemon"). One free model's result as RESULT and `status` show it, the free models'
// context and gate, and the calibration document a free model's activation writes
// (calibrations/DEVICE.MODEL.json, schema 1, "pose_source": "free"):
//
//   "requested":  the model configured ("magellipsoid"); "model": the model fitted ("magsphere"
//                 when the data could not carry an ellipsoid), "note" says why
//   "params", "parameter_order", "covariance", "rank", "chi2", "dof", "p_value", "fit_check",
//   "gate": {"pass", "reasons"}, "coverage", "weak", "undetermined", "misfit_before",
//   "misfit_after", "relative_scale", "advice"
//   "bias_window": {"t0_s","t1_s"} on the station's host clock, with a drift model
//   "upstream":   {"model", "theta"}: the estimate this one builds on (gyro9's accel9), which the
//                 live correction of gyro9g's g-sensitivity needs
//   "context":    the free models' context (gravity, field magnitude, latitude, drift per triad)
//   "free_gate":  the limits the gate applied, so that a re-fit gates alike
//   "provenance": {"records": the static intervals, with the triads the model uses (and a
//                 gyroscope's moves), "device_identity"}
//
// A document holds its evidence: the report re-fits it without the journal.

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/analysis/free_advice.h"
#include "core/estimation/free_calibrator.h"

namespace turncal::protocol {

nlohmann::json ToJson(const FreeContext& context);
// Absent keys keep *out's; false with a message when a key is malformed or the context invalid.
bool ParseFreeContext(const nlohmann::json& j, FreeContext* out, std::string* error);

// The gate's limits: {"min_coverage", "min_relative_singular", "precision": null or
// {"min_dof", "min_p_value", "tolerances": {"scale_factor", ...}, "parameters": {NAME: sigma}}}.
nlohmann::json FreeGateJson(const FreeCalibratorOptions& options);
// The largest region without a direction (core/analysis/sphere_coverage.h): `direction`, `name`
// (the case's nearest axis, edge or corner), `radius_deg`, `empty_area_fraction`.
nlohmann::json ToJson(const CoverageGap& gap);
bool ParseFreeGate(const nlohmann::json& j, FreeCalibratorOptions* out, std::string* error);

// One free model's result: {"requested", "model", "note", "ok", "error", "intervals",
// "params": {NAME: {"value", "sigma"}}, "rank", "condition", "chi2", "dof", "p_value",
// "covariance_scale", "fit_check": {"verdict", "cause"}, "coverage": {"filled", "total",
// "fraction"}, "weak", "undetermined", "weakest_direction", "misfit_before", "misfit_after" ([{
// "kind", "count", "rms", "max"}]), "relative_scale", "bias_window" (host clock), "warnings",
// "gate": {"pass", "reasons"}, "advice": {"text", "sigma_ratio"}}. sigma is null where
// undetermined.
nlohmann::json FreeResultJson(const FreeModelResult& result,
                              const std::optional<OrientationAdvice>& advice);

struct FreeCalibrationInput {
  std::string device;
  int version = 0;
  const FreeModelResult* result = nullptr;    // required, with an estimate
  const FreeModelResult* upstream = nullptr;  // the estimate it builds on, or null
  std::optional<OrientationAdvice> advice;
  FreeContext context;
  FreeCalibratorOptions options;
  std::string sensor_class;
  std::vector<FreeInterval> intervals;  // every interval the fit saw
  nlohmann::json identity;              // the device dialogue's (null in replays)
};
// The document, with "software" set (the caller adds "time").
nlohmann::json FreeCalibrationJson(const FreeCalibrationInput& input);

bool IsFreeCalibration(const nlohmann::json& j);

struct FreeCalibrationDocument {
  std::string device, requested, model, software, time;
  int version = 0;
  Eigen::VectorXd theta;       // in the fitted model's order
  Eigen::MatrixXd covariance;  // empty when absent or not finite
  std::string upstream_model;
  Eigen::VectorXd upstream_theta;  // empty without an upstream
  std::optional<TimeWindow> bias_window;
  FreeContext context;
  FreeCalibratorOptions options;
  std::vector<FreeInterval> intervals;  // provenance.records
  nlohmann::json identity;
  nlohmann::json override_who;  // null unless published by operator override
};
// False with a message naming the key when the document is not a free calibration of a known
// free model with a finite value for each of its parameters.
bool ParseFreeCalibration(const nlohmann::json& j, FreeCalibrationDocument* out,
                          std::string* error);

}  // namespace turncal::protocol
