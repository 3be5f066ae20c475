#include "sim/thermal_truth.h"

#include "sim/synthetic.h"

namespace turncal {

double ClassTempco(const MeasurementModel& model, const SensorClass& sensor, int parameter) {
  const ParameterInfo& p = model.parameters()[static_cast<std::size_t>(parameter)];
  if (p.kind != ParameterKind::kSensor) return 0.0;
  const SensorKind kind = model.sensor();
  switch (p.unit) {
    case ParameterUnit::kScaleFactor:
      return kind == SensorKind::kGyroscope       ? sensor.gyr_scale_tempco
             : kind == SensorKind::kAccelerometer ? sensor.acc_scale_tempco
                                                  : sensor.mag_scale_tempco;
    case ParameterUnit::kAngle:
      return sensor.misalignment_tempco;
    case ParameterUnit::kAcceleration:
      return sensor.acc_bias_tempco;
    case ParameterUnit::kField:
      return sensor.mag_bias_tempco;
    case ParameterUnit::kGain:
      return sensor.mag_scale_tempco;
    case ParameterUnit::kAngularRate:
      return sensor.gyr_bias_tempco;
    case ParameterUnit::kGSensitivity:
    case ParameterUnit::kSecondOrder:
      return 0.0;
  }
  return 0.0;
}

ThermalBasis ThermalTruthBasis(const MeasurementModel& model, const SensorClass& sensor,
                               double t0_c) {
  ThermalBasis basis = ThermalBasis::Constant(model.num_parameters(), t0_c);
  for (int p = 0; p < model.num_parameters(); ++p) {
    if (ClassTempco(model, sensor, p) > 0) basis.orders[static_cast<std::size_t>(p)] = 2;
  }
  return basis;
}

ThermalTruth DrawThermalTruth(const MeasurementModel& model, const SensorClass& sensor, double t0_c,
                              std::mt19937_64* rng) {
  const Eigen::VectorXd theta0 = DrawTruth(model, sensor, rng);
  return DrawThermalTruthAbout(model, sensor, theta0, t0_c, rng);
}

ThermalTruth DrawThermalTruthAbout(const MeasurementModel& model, const SensorClass& sensor,
                                   const Eigen::VectorXd& theta0, double t0_c,
                                   std::mt19937_64* rng) {
  ThermalTruth truth;
  truth.basis = ThermalTruthBasis(model, sensor, t0_c);
  truth.coefficients = Eigen::VectorXd::Zero(truth.basis.num_coefficients());
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int p = 0; p < model.num_parameters(); ++p) {
    truth.coefficients[truth.basis.index(p, 0)] = theta0[p];
    const double tempco = ClassTempco(model, sensor, p);
    if (tempco <= 0) continue;
    truth.coefficients[truth.basis.index(p, 1)] = tempco * normal(*rng);
    truth.coefficients[truth.basis.index(p, 2)] = 0.3 * tempco / 40.0 * normal(*rng);
  }
  return truth;
}

}  // namespace turncal
