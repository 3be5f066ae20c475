#pragma once
// A sensor's parameters as functions of its die temperature, drawn from its class (issue 36;
// SENSORS.md "Temperature"): the truth of a calibration over temperature.
//
// Each sensor parameter (ParameterKind::kSensor: biases, scale factors, misalignments, soft
// iron, a gyroscope's g-sensitivity stays constant) gets a quadratic in (T - t0): its linear
// coefficient drawn N(0, the class's temperature coefficient), its quadratic one N(0, 0.3 x that
// / 40 degC), so that over +-40 degC the curve bends by about a third of the slope's excursion
// ("smooth, often quadratic or cubic over the range"). Mounting and installation parameters
// (eps, beta) do not depend on temperature. The value at t0 is DrawTruth's.

#include <random>

#include "core/estimation/sensor_class.h"
#include "core/modeling/measurement_model.h"
#include "core/modeling/thermal_basis.h"

namespace turncal {

struct ThermalTruth {
  ThermalBasis basis;  // unscaled: coefficients per degree C^j about basis.t0_c
  Eigen::VectorXd coefficients;

  Eigen::VectorXd ThetaAt(double temp_c) const { return basis.Theta(coefficients, temp_c); }
};

// The class's temperature coefficient of one parameter (0 for mounting, installation and
// g-sensitivity parameters).
double ClassTempco(const MeasurementModel& model, const SensorClass& sensor, int parameter);

// The truth's polynomials: order 2 for every parameter with a class temperature coefficient,
// 0 for the others.
ThermalBasis ThermalTruthBasis(const MeasurementModel& model, const SensorClass& sensor,
                               double t0_c);
// theta0 from DrawTruth, then the coefficients.
ThermalTruth DrawThermalTruth(const MeasurementModel& model, const SensorClass& sensor, double t0_c,
                              std::mt19937_64* rng);
// The coefficients about a given theta0 (the value at t0_c).
ThermalTruth DrawThermalTruthAbout(const MeasurementModel& model, const SensorClass& sensor,
                                   const Eigen::VectorXd& theta0, double t0_c,
                                   std::mt19937_64* rng);

}  // namespace turncal
