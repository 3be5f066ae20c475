#pragma once
// The pipeline Monte Carlo in a climate chamber (`turncal montecarlo --pipeline --chamber`,
// issue 36): which temperatures a calibration over temperature is judged at, what is scored, and
// the scoring of one run's MODEL@T result against the simulator's truth over temperature.

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/modeling/measurement_model.h"
#include "core/modeling/thermal_basis.h"
#include "sim/chamber.h"
#include "sim/thermal_truth.h"

namespace turncal::montecarlo {

// Temperatures between those the chamber visits: the midpoints between its distinct set-points
// (the start included) when it has three or more, else the range's quarter points.
std::vector<double> DefaultHeldOutTemperatures(const ChamberProfile& chamber);

// What a run scores, in order: with `coefficients` each coefficient of the truth's polynomials
// ("bx", "bx*dT", ...: the station fits the truth's orders), then every parameter at every held-out
// temperature ("bx@12.5C").
std::vector<std::string> ThermalScoredNames(const MeasurementModel& model,
                                            const ThermalBasis* coefficients,
                                            const std::vector<double>& held_out_c);

// z of one run's result `m` (a MODEL@T entry of RESULT, or its document) against `truth`, whose
// biases are moved by `bias_offset` (the wander over the calibration's bias window), in the order
// of ThermalScoredNames. False with a reason when the result cannot be read.
bool ScoreThermalRun(const MeasurementModel& model, const nlohmann::json& m,
                     const ThermalTruth& truth, const Eigen::Vector3d& bias_offset,
                     bool coefficients, const std::vector<double>& held_out_c, Eigen::VectorXd* z,
                     std::string* error);

}  // namespace turncal::montecarlo
