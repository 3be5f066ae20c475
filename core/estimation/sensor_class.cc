#include "core/estimation/sensor_class.h"

#include "core/frames/units.h"

namespace turncal {

namespace {
constexpr double kMicroG = 1e-6 * 9.80665;
}  // namespace

SensorClass IndustrialClass() {
  SensorClass c;
  c.name = "industrial";
  c.acc_noise_density = 60 * kMicroG;            // MTi-300, 60 ug/sqrt(Hz)
  c.acc_bias_instability = 4e-4;                 // between poses over minutes (SENSORS.md)
  c.acc_turn_on_bias = 2e-3 * 9.80665;           // 2 mg
  c.acc_scale_sigma = 500e-6;                    // 500 ppm
  c.acc_second_order = 30e-6 / 9.80665;          // 30 ug/g^2 (a MEMS accelerometer's, assumed)
  c.misalignment_sigma_rad = 0.05 * kRadPerDeg;  // 0.05 deg
  c.mag_noise_rms = 0.5e-3;                      // 0.5 mG
  c.mag_bias_instability = 0.1e-3;
  c.mag_hard_iron_sigma = 0.05;
  c.mag_soft_iron_sigma = 0.02;
  c.rate_hz = 500;
  c.gyr_noise_density = 0.01 * kRadPerDeg;          // MTi-300: 0.01 deg/s/sqrt(Hz)
  c.gyr_turn_on_bias = 0.2 * kRadPerDeg;            // 0.05-0.5 deg/s
  c.gyr_bias_instability = 10 * kRadPerDeg / 3600;  // MTi-300: 10 deg/h
  c.gyr_scale_sigma = 500e-6;
  c.gyr_g_sensitivity = 0.003 * kRadPerDeg / 9.80665;  // MTi-300: 0.003 deg/s/g
  // SENSORS.md "Temperature": the residual after the factory's model.
  c.acc_bias_tempco = 0.03e-3 * 9.80665;   // 0.01-0.05 mg/degC
  c.acc_scale_tempco = 30e-6;              // 10-50 ppm/degC
  c.gyr_bias_tempco = 0.005 * kRadPerDeg;  // 0.001-0.01 deg/s/degC
  c.gyr_scale_tempco = 50e-6;              // 20-100 ppm/degC
  c.mag_bias_tempco = 0.02e-3;             // not in SENSORS.md: 0.02 mG/degC
  c.mag_scale_tempco = 30e-6;              // not in SENSORS.md: as the accelerometer's scale
  c.misalignment_tempco = 1e-6;            // not in SENSORS.md: 1 urad/degC
  return c;
}

SensorClass ConsumerClass() {
  SensorClass c;
  c.name = "consumer";
  c.acc_noise_density = 200 * kMicroG;          // 200 ug/sqrt(Hz)
  c.acc_bias_instability = 0.02;                // SENSORS.md: 0.02 m/s^2
  c.acc_turn_on_bias = 20e-3 * 9.80665;         // 20 mg
  c.acc_scale_sigma = 3e-3;                     // 0.3 %
  c.acc_second_order = 300e-6 / 9.80665;        // 300 ug/g^2 (assumed)
  c.misalignment_sigma_rad = 0.1 * kRadPerDeg;  // 0.1 deg
  c.mag_noise_rms = 0.5e-3;
  c.mag_bias_instability = 0.2e-3;
  c.mag_hard_iron_sigma = 0.1;
  c.mag_soft_iron_sigma = 0.03;
  c.rate_hz = 100;
  c.gyr_noise_density = 0.05 * kRadPerDeg;          // 0.05-0.1 deg/s/sqrt(Hz)
  c.gyr_turn_on_bias = 0.7 * kRadPerDeg;            // 0.5-1 deg/s
  c.gyr_bias_instability = 50 * kRadPerDeg / 3600;  // ~50 deg/h
  c.gyr_scale_sigma = 3e-3;
  c.gyr_g_sensitivity = 0.1 * kRadPerDeg / 9.80665;  // not specified (SENSORS.md); 0.1 deg/s/g
  c.acc_quantum = 0.15e-3 * 9.80665;                 // 16 bits over +-5 g (SENSORS.md)
  c.gyr_quantum = 0.0092 * kRadPerDeg;               // 16 bits over +-300 deg/s
  c.mag_quantum = 2.4 / 65536;                       // 16 bits over +-1.2 G
  // SENSORS.md "Temperature": uncompensated.
  c.acc_bias_tempco = 1e-3 * 9.80665;     // +-1 mg/K
  c.acc_scale_tempco = 3e-4;              // +-0.03 %/K
  c.gyr_bias_tempco = 0.05 * kRadPerDeg;  // +-0.05 deg/s/K
  c.gyr_scale_tempco = 2e-4;              // +-0.02 %/K
  c.mag_bias_tempco = 0.2e-3;             // not in SENSORS.md: 0.2 mG/K
  c.mag_scale_tempco = 3e-4;              // not in SENSORS.md: as the accelerometer's scale
  c.misalignment_tempco = 10e-6;          // not in SENSORS.md: 10 urad/K
  return c;
}

bool SensorClassByName(const std::string& name, SensorClass* out) {
  if (name == "industrial") {
    *out = IndustrialClass();
    return true;
  }
  if (name == "consumer") {
    *out = ConsumerClass();
    return true;
  }
  return false;
}

CalibratorOptions OptionsForClass(const MeasurementModel& model, const SensorClass& sensor) {
  CalibratorOptions o;
  o.model = model.name();
  o.context = model.context();
  switch (model.sensor()) {
    case SensorKind::kAccelerometer:
      o.pose_offset_sigma = sensor.acc_bias_instability;
      o.noise_density = sensor.acc_noise_density;
      break;
    case SensorKind::kMagnetometer:
      o.pose_offset_sigma = sensor.mag_bias_instability;
      o.noise_density = 0.0;
      break;
    case SensorKind::kGyroscope:
      o.pose_offset_sigma = sensor.gyr_bias_instability;
      o.noise_density = sensor.gyr_noise_density;
      break;
  }
  return o;
}

BiasDrift DriftForClass(const SensorClass& sensor, SensorKind kind) {
  BiasDrift d;
  double instability = 0.0, random_walk = 0.0;
  switch (kind) {
    case SensorKind::kAccelerometer:
      instability = sensor.acc_bias_instability, random_walk = sensor.acc_random_walk;
      break;
    case SensorKind::kMagnetometer:
      instability = sensor.mag_bias_instability, random_walk = sensor.mag_random_walk;
      break;
    case SensorKind::kGyroscope:
      instability = sensor.gyr_bias_instability, random_walk = sensor.gyr_random_walk;
      break;
  }
  d.gm_sigma = Eigen::Vector3d::Constant(instability);
  d.gm_tau_s = sensor.bias_tau_s;
  d.rw_density = Eigen::Vector3d::Constant(random_walk);
  d.warmup_sigma = d.gm_sigma * sensor.warmup_in_instabilities;
  d.warmup_tau_s = sensor.warmup_tau_s;
  return d;
}

CalibratorOptions DriftOptionsForClass(const MeasurementModel& model, const SensorClass& sensor) {
  CalibratorOptions o = OptionsForClass(model, sensor);
  o.drift = DriftForClass(sensor, model.sensor());
  o.pose_offset_sigma = 0.0;
  return o;
}

Eigen::Matrix3d ExpectedPoseSqrtInformation(const MeasurementModel& model,
                                            const SensorClass& sensor,
                                            const CalibratorOptions& options, double dwell_s,
                                            double rate_hz) {
  double white = 0.0;
  switch (model.sensor()) {
    case SensorKind::kAccelerometer:
      white = sensor.acc_noise_density * sensor.acc_noise_density / (2 * dwell_s);
      break;
    case SensorKind::kMagnetometer:
      white = sensor.mag_noise_rms * sensor.mag_noise_rms / (rate_hz * dwell_s);
      break;
    case SensorKind::kGyroscope:
      white = sensor.gyr_noise_density * sensor.gyr_noise_density / (2 * dwell_s);
      break;
  }
  const double var = white + options.pose_offset_sigma * options.pose_offset_sigma;
  return Eigen::Matrix3d::Identity() / std::sqrt(var);
}

}  // namespace turncal
