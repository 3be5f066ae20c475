#pragma once
// In-memory synthetic calibration data with known truth: truth drawn near nominal with a sensor
// class's error magnitudes, and the per-pose statistics a stationary window would give. Pure
// computation with an explicit random generator, for tests, the Monte Carlo check and the
// core-level demonstration. (The sample-level session and the byte-level capture build on the
// same classes: sim/session_sim.h, sim/capture.h.)

#include <random>

#include "core/estimation/pose_record.h"
#include "core/estimation/sensor_class.h"
#include "core/modeling/measurement_model.h"
#include "core/planning/pose_designs.h"

namespace turncal {

// Truth near nominal with the class's error magnitudes; beta uniform in [-0.3, 0.3] rad. mag22's
// truth is in the gauge of Calibrator (det K_ = 1, dB orthogonal to R3(beta) B_NED).
Eigen::VectorXd DrawTruth(const MeasurementModel& model, const SensorClass& sensor,
                          std::mt19937_64* rng);

// The record a stationary window of `dwell_s` at `pose` would give: the true measurement plus
// white noise averaged over the window and a bias-instability offset, with the sample covariance
// of the white noise (what the window's samples show). The offset is invisible inside one
// window: the calibrator must be told of it (CalibratorOptions::pose_offset_sigma).
PoseRecord SimulateRecord(const MeasurementModel& model, const Eigen::VectorXd& truth,
                          const TablePose& pose, const SensorClass& sensor, double dwell_s,
                          std::mt19937_64* rng);

}  // namespace turncal
