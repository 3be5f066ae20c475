#pragma once
// The sensor classes of SENSORS.md (noise, error magnitudes, rates) and the calibrator options
// that match them: what the station assumes of a sensor before its own data say more.

#include <string>

#include "core/estimation/calibrator.h"
#include "core/modeling/measurement_model.h"

namespace turncal {

// Noise and error magnitudes of one sensor class (SENSORS.md "Two classes").
struct SensorClass {
  std::string name;
  // Accelerometer, m/s^2.
  double acc_noise_density = 0.0;     // white, per sqrt(Hz)
  double acc_bias_instability = 0.0;  // 1 sigma offset of a pose mean from bias wander
  double acc_turn_on_bias = 0.0;      // 1 sigma
  double acc_scale_sigma = 0.0;       // 1 sigma relative
  double misalignment_sigma_rad = 0.0;
  // Magnetometer, Gauss.
  double mag_noise_rms = 0.0;  // per sample at `rate_hz`
  double mag_bias_instability = 0.0;
  double mag_hard_iron_sigma = 0.0;  // 1 sigma of b
  double mag_soft_iron_sigma = 0.0;  // 1 sigma of G's deviation from the mounting
  double rate_hz = 100.0;
  // Correlation time of the bias instability (first-order Gauss-Markov, both triads): minutes
  // for MEMS (SENSORS.md); the session simulator's default.
  double bias_tau_s = 100.0;
  // The warm-up the calibrator allows for after power-on (BiasDrift::warmup_sigma), in units of
  // the bias instability, and its time constant: none by default (an allowance the data do not
  // show makes chi^2 too small, docs/ACCURACY.md); the simulator draws none unless asked.
  double warmup_in_instabilities = 0.0;
  double warmup_tau_s = 60.0;
  // Bias random walk of each triad, unit per sqrt(s): none for the datasheet classes; a noise
  // prior measured on the sensor may have one ([station] acc_random_walk, mag_random_walk).
  double acc_random_walk = 0.0;
  double mag_random_walk = 0.0;
  // Gyroscope, rad/s.
  double gyr_noise_density = 0.0;     // per sqrt(Hz)
  double gyr_turn_on_bias = 0.0;      // 1 sigma
  double gyr_bias_instability = 0.0;  // 1 sigma of the Gauss-Markov wander (tau bias_tau_s)
  double gyr_scale_sigma = 0.0;       // 1 sigma relative (the misalignment: misalignment_sigma_rad)
  double acc_second_order = 0.0;      // 1 sigma of each K2, per m/s^2 (accel15)
  double gyr_g_sensitivity = 0.0;     // 1 sigma of each B_g entry, rad/s per m/s^2
  double gyr_random_walk = 0.0;       // bias random walk, rad/s/sqrt(s)
  // Quantisation steps of a 16-bit ADC (0 = floats on the wire, no quantisation).
  double acc_quantum = 0.0;  // m/s^2
  double gyr_quantum = 0.0;  // rad/s
  double mag_quantum = 0.0;  // Gauss
  // Temperature coefficients, 1 sigma per degree C of the die (SENSORS.md "Temperature"; issue 36):
  // the linear term of each sensor parameter's dependence on temperature that the simulator draws
  // (sim/thermal_truth.h; a quadratic term is drawn from the same figure). Mounting and
  // installation parameters do not depend on temperature.
  double acc_bias_tempco = 0.0;      // m/s^2 per degree C
  double acc_scale_tempco = 0.0;     // relative per degree C
  double gyr_bias_tempco = 0.0;      // rad/s per degree C
  double gyr_scale_tempco = 0.0;     // relative per degree C
  double mag_bias_tempco = 0.0;      // Gauss per degree C
  double mag_scale_tempco = 0.0;     // relative (soft iron, gain entries) per degree C
  double misalignment_tempco = 0.0;  // rad per degree C
};

// "industrial" (~3DM-GX5-25, MTi-300) and "consumer" (~3DM-GX2, MTi/MTx mark II).
SensorClass IndustrialClass();
SensorClass ConsumerClass();
// By name; false when unknown.
bool SensorClassByName(const std::string& name, SensorClass* out);

// Calibrator options matching the class's noise for `model` (the pose-to-pose offset and the
// white-noise density of the triad the model uses: the accelerometer's and gyroscope's densities;
// the magnetometer's per-sample noise has no density floor).
CalibratorOptions OptionsForClass(const MeasurementModel& model, const SensorClass& sensor);

// The class's bias drift of one triad: Gauss-Markov sigma = its bias instability with tau =
// bias_tau_s, its random walk, and the warm-up allowance.
BiasDrift DriftForClass(const SensorClass& sensor, SensorKind kind);

// The same with the bias instability as a Gauss-Markov process in time (DriftForClass) instead of
// an independent offset per pose: what the station uses, for records that carry their time
// windows.
CalibratorOptions DriftOptionsForClass(const MeasurementModel& model, const SensorClass& sensor);

// The 1/sigma a planned pose's mean will have from white noise (and options' independent
// pose_offset_sigma), for the pose planner: the accelerometer's density over the dwell, the
// magnetometer's per-sample noise over the dwell's samples at `rate_hz`.
Eigen::Matrix3d ExpectedPoseSqrtInformation(const MeasurementModel& model,
                                            const SensorClass& sensor,
                                            const CalibratorOptions& options, double dwell_s,
                                            double rate_hz);

}  // namespace turncal
