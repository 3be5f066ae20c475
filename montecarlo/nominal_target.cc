#include "montecarlo/nominal_target.h"

#include "core/analysis/publish_gate.h"

namespace turncal::montecarlo {

PlanningTarget NominalPlanningTarget(const MeasurementModel& model, const SensorClass& sensor,
                                     bool drift_model, double dwell_s, double rate_hz) {
  const CalibratorOptions o =
      drift_model ? DriftOptionsForClass(model, sensor) : OptionsForClass(model, sensor);
  PlanningTarget t;
  t.model = &model;
  t.theta = model.nominal();
  t.sqrt_information = ExpectedPoseSqrtInformation(model, sensor, o, dwell_s, rate_hz);
  t.drift = o.drift;
  t.pose_offset_sigma = o.pose_offset_sigma;
  if (model.sensor() == SensorKind::kGyroscope) {
    t.noise_density = o.noise_density;
    t.rate_accuracy = o.rate_accuracy;
  }
  GateDefaultsForClass(sensor.name, &t.gate);
  return t;
}

}  // namespace turncal::montecarlo
