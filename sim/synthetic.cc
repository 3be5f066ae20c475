#include "sim/synthetic.h"

#include <cmath>

#include "core/frames/units.h"
#include "core/modeling/mag22_gauge.h"

namespace turncal {

Eigen::VectorXd DrawTruth(const MeasurementModel& model, const SensorClass& sensor,
                          std::mt19937_64* rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> heading(-0.3, 0.3);
  Eigen::VectorXd theta = model.nominal();
  const bool accel = model.sensor() == SensorKind::kAccelerometer;
  const bool gyro = model.sensor() == SensorKind::kGyroscope;
  const double scale_sigma = gyro    ? sensor.gyr_scale_sigma
                             : accel ? sensor.acc_scale_sigma
                                     : sensor.mag_soft_iron_sigma;
  for (int i = 0; i < model.num_parameters(); ++i) {
    const ParameterInfo& p = model.parameters()[i];
    if (p.name == "beta") {
      theta[i] = heading(*rng);
    } else if (p.unit == ParameterUnit::kScaleFactor) {
      theta[i] += scale_sigma * normal(*rng);
    } else if (p.unit == ParameterUnit::kAngularRate) {
      theta[i] += sensor.gyr_turn_on_bias * normal(*rng);
    } else if (p.unit == ParameterUnit::kGSensitivity) {
      theta[i] += sensor.gyr_g_sensitivity * normal(*rng);
    } else if (p.unit == ParameterUnit::kAngle) {
      theta[i] += sensor.misalignment_sigma_rad * normal(*rng);
    } else if (p.unit == ParameterUnit::kAcceleration) {
      theta[i] += sensor.acc_turn_on_bias * normal(*rng);
    } else if (p.unit == ParameterUnit::kGain) {
      theta[i] += sensor.mag_soft_iron_sigma * normal(*rng);
    } else if (p.unit == ParameterUnit::kField) {
      theta[i] += sensor.mag_hard_iron_sigma * normal(*rng);
    } else if (p.unit == ParameterUnit::kSecondOrder) {
      theta[i] += sensor.acc_second_order * normal(*rng);
    }
  }
  if (model.gauge_dimension() > 0) ApplyMag22Gauge(model, &theta);
  return theta;
}

PoseRecord SimulateRecord(const MeasurementModel& model, const Eigen::VectorXd& truth,
                          const TablePose& pose, const SensorClass& sensor, double dwell_s,
                          std::mt19937_64* rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  const SensorKind kind = model.sensor();
  const auto count = static_cast<std::int64_t>(std::llround(dwell_s * sensor.rate_hz));
  // Per-sample white-noise sigma: density * sqrt(rate / 2) for a sensor band-limited at Nyquist;
  // the mean of n samples has sigma_sample / sqrt(n) = density / sqrt(2 dwell).
  const double sample_sigma = kind == SensorKind::kAccelerometer
                                  ? sensor.acc_noise_density * std::sqrt(sensor.rate_hz / 2.0)
                              : kind == SensorKind::kGyroscope
                                  ? sensor.gyr_noise_density * std::sqrt(sensor.rate_hz / 2.0)
                                  : sensor.mag_noise_rms;
  const double offset_sigma = kind == SensorKind::kAccelerometer ? sensor.acc_bias_instability
                              : kind == SensorKind::kGyroscope   ? sensor.gyr_bias_instability
                                                                 : sensor.mag_bias_instability;
  const double white_mean_var = sample_sigma * sample_sigma / static_cast<double>(count);

  TriadStats stats;
  stats.count = count;
  stats.mean = model.Predict(truth, pose);
  for (int i = 0; i < 3; ++i) {
    stats.mean[i] += std::sqrt(white_mean_var) * normal(*rng) + offset_sigma * normal(*rng);
  }
  // The sample covariance of n white samples: a Wishart draw, approximated per axis by the
  // chi-square spread of its diagonal (enough for n in the hundreds).
  stats.covariance = Eigen::Matrix3d::Zero();
  const double spread = std::sqrt(2.0 / static_cast<double>(std::max<std::int64_t>(count - 1, 1)));
  for (int i = 0; i < 3; ++i) {
    stats.covariance(i, i) =
        sample_sigma * sample_sigma * std::max(0.1, 1.0 + spread * normal(*rng));
  }

  PoseRecord record;
  record.pose = pose;
  record.t_start_s = 0.0;
  record.t_end_s = dwell_s;
  (kind == SensorKind::kAccelerometer ? record.acc
   : kind == SensorKind::kGyroscope   ? record.gyr
                                      : record.mag) = stats;
  return record;
}

}  // namespace turncal
