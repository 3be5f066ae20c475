#include "core/synthetic.h"

#include <cmath>

#include "core/mag22_gauge.h"
#include "core/units.h"

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
  c.misalignment_sigma_rad = 0.05 * kRadPerDeg;  // 0.05 deg
  c.mag_noise_rms = 0.5e-3;                      // 0.5 mG
  c.mag_bias_instability = 0.1e-3;
  c.mag_hard_iron_sigma = 0.05;
  c.mag_soft_iron_sigma = 0.02;
  c.rate_hz = 500;
  c.gyr_noise_density = 0.01 * kRadPerDeg;  // MTi-300: 0.01 deg/s/sqrt(Hz)
  c.gyr_turn_on_bias = 0.2 * kRadPerDeg;    // 0.05-0.5 deg/s
  return c;
}

SensorClass ConsumerClass() {
  SensorClass c;
  c.name = "consumer";
  c.acc_noise_density = 200 * kMicroG;          // 200 ug/sqrt(Hz)
  c.acc_bias_instability = 0.02;                // SENSORS.md: 0.02 m/s^2
  c.acc_turn_on_bias = 20e-3 * 9.80665;         // 20 mg
  c.acc_scale_sigma = 3e-3;                     // 0.3 %
  c.misalignment_sigma_rad = 0.1 * kRadPerDeg;  // 0.1 deg
  c.mag_noise_rms = 0.5e-3;
  c.mag_bias_instability = 0.2e-3;
  c.mag_hard_iron_sigma = 0.1;
  c.mag_soft_iron_sigma = 0.03;
  c.rate_hz = 100;
  c.gyr_noise_density = 0.05 * kRadPerDeg;  // 0.05-0.1 deg/s/sqrt(Hz)
  c.gyr_turn_on_bias = 0.7 * kRadPerDeg;    // 0.5-1 deg/s
  c.acc_quantum = 0.15e-3 * 9.80665;        // 16 bits over +-5 g (SENSORS.md)
  c.gyr_quantum = 0.0092 * kRadPerDeg;      // 16 bits over +-300 deg/s
  c.mag_quantum = 2.4 / 65536;              // 16 bits over +-1.2 G
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

Eigen::VectorXd DrawTruth(const MeasurementModel& model, const SensorClass& sensor,
                          std::mt19937_64* rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> heading(-0.3, 0.3);
  Eigen::VectorXd theta = model.nominal();
  const bool accel = model.sensor() == SensorKind::kAccelerometer;
  for (int i = 0; i < model.num_parameters(); ++i) {
    const ParameterInfo& p = model.parameters()[i];
    if (p.name == "beta") {
      theta[i] = heading(*rng);
    } else if (p.unit == ParameterUnit::kScaleFactor) {
      theta[i] += (accel ? sensor.acc_scale_sigma : sensor.mag_soft_iron_sigma) * normal(*rng);
    } else if (p.unit == ParameterUnit::kAngle) {
      theta[i] += sensor.misalignment_sigma_rad * normal(*rng);
    } else if (p.unit == ParameterUnit::kAcceleration) {
      theta[i] += sensor.acc_turn_on_bias * normal(*rng);
    } else if (p.unit == ParameterUnit::kGain) {
      theta[i] += sensor.mag_soft_iron_sigma * normal(*rng);
    } else if (p.unit == ParameterUnit::kField) {
      theta[i] += sensor.mag_hard_iron_sigma * normal(*rng);
    }
  }
  if (model.gauge_dimension() > 0) ApplyMag22Gauge(model, &theta);
  return theta;
}

CalibratorOptions OptionsForClass(const MeasurementModel& model, const SensorClass& sensor) {
  CalibratorOptions o;
  o.model = model.name();
  o.context = model.context();
  const bool accel = model.sensor() == SensorKind::kAccelerometer;
  o.pose_offset_sigma = accel ? sensor.acc_bias_instability : sensor.mag_bias_instability;
  o.noise_density = accel ? sensor.acc_noise_density : 0.0;
  return o;
}

CalibratorOptions DriftOptionsForClass(const MeasurementModel& model, const SensorClass& sensor) {
  CalibratorOptions o = OptionsForClass(model, sensor);
  o.drift.gm_sigma = Eigen::Vector3d::Constant(o.pose_offset_sigma);
  o.drift.gm_tau_s = sensor.bias_tau_s;
  o.drift.warmup_sigma = o.drift.gm_sigma * sensor.warmup_in_instabilities;
  o.drift.warmup_tau_s = sensor.warmup_tau_s;
  o.pose_offset_sigma = 0.0;
  return o;
}

Eigen::Matrix3d ExpectedPoseSqrtInformation(const MeasurementModel& model,
                                            const SensorClass& sensor,
                                            const CalibratorOptions& options, double dwell_s,
                                            double rate_hz) {
  const bool accel = model.sensor() == SensorKind::kAccelerometer;
  const double white = accel ? sensor.acc_noise_density * sensor.acc_noise_density / (2 * dwell_s)
                             : sensor.mag_noise_rms * sensor.mag_noise_rms / (rate_hz * dwell_s);
  const double var = white + options.pose_offset_sigma * options.pose_offset_sigma;
  return Eigen::Matrix3d::Identity() / std::sqrt(var);
}

std::vector<TablePose> RandomPoses(int n, std::mt19937_64* rng) {
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<TablePose> poses;
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3d d;
    do {
      d = Eigen::Vector3d(uniform(*rng), uniform(*rng), uniform(*rng));
    } while (d.norm() > 1.0 || d.norm() < 0.1);
    poses.push_back(PoseWithDownAlong(d, M_PI * uniform(*rng)));
  }
  return poses;
}

std::vector<TablePose> CubePoses26() {
  std::vector<TablePose> poses;
  int k = 0;
  for (int x = -1; x <= 1; ++x)
    for (int y = -1; y <= 1; ++y)
      for (int z = -1; z <= 1; ++z) {
        if (x == 0 && y == 0 && z == 0) continue;
        poses.push_back(PoseWithDownAlong(Eigen::Vector3d(x, y, z), (k++ % 4) * M_PI / 2));
      }
  return poses;
}

std::vector<TablePose> AboutZPoses(int n) {
  std::vector<TablePose> poses;
  for (int i = 0; i < n; ++i) poses.push_back(TablePose{0.0, 0.0, 2 * M_PI * i / n});
  return poses;
}

PoseRecord SimulateRecord(const MeasurementModel& model, const Eigen::VectorXd& truth,
                          const TablePose& pose, const SensorClass& sensor, double dwell_s,
                          std::mt19937_64* rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  const bool accel = model.sensor() == SensorKind::kAccelerometer;
  const auto count = static_cast<std::int64_t>(std::llround(dwell_s * sensor.rate_hz));
  // Per-sample white-noise sigma: density * sqrt(rate / 2) for a sensor band-limited at Nyquist;
  // the mean of n samples has sigma_sample / sqrt(n) = density / sqrt(2 dwell).
  const double sample_sigma =
      accel ? sensor.acc_noise_density * std::sqrt(sensor.rate_hz / 2.0) : sensor.mag_noise_rms;
  const double offset_sigma = accel ? sensor.acc_bias_instability : sensor.mag_bias_instability;
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
  (accel ? record.acc : record.mag) = stats;
  return record;
}

}  // namespace turncal
