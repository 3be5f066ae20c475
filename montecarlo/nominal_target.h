#pragma once
// The planner's target for a model before any pose is captured, from its sensor class alone: what
// `turncal plan` plans for and what `turncal montecarlo --pipeline --plan planner` simulates.
// (Its place is beside TargetFromCalibrator in core/planning/, which plans from a calibrator's
// poses; it sits here until core/ is open for it.)

#include "core/estimation/sensor_class.h"
#include "core/modeling/measurement_model.h"
#include "core/planning/pose_planner.h"

namespace turncal::montecarlo {

// `model` (not owned; it must outlive the target) at its nominal parameters, a new pose weighed
// as the class's white noise (and independent pose offset) over `dwell_s` at `rate_hz`
// (ExpectedPoseSqrtInformation), with the class's drift as a process in time when `drift_model`
// (DriftOptionsForClass) or independent poses otherwise (OptionsForClass), the class's gate
// tolerances, and for a gyroscope the calibrator's noise density and rate accuracy. No captured
// poses.
PlanningTarget NominalPlanningTarget(const MeasurementModel& model, const SensorClass& sensor,
                                     bool drift_model, double dwell_s, double rate_hz);

}  // namespace turncal::montecarlo
