// StationOptions (daemon/station/station.h): its validity, the sensor class it resolves, the pose
// source's names.
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>

#include "core/estimation/sensor_class.h"
#include "core/modeling/free_model.h"
#include "daemon/station/station.h"
#include "daemon/station/thermal_pipeline.h"

namespace turncal::daemon {

bool StationOptions::IsValid(std::string* error) const {
  if (!sequencer.IsValid(error) || !gate.IsValid(error) || !table.IsValid(error)) return false;
  if (!context.IsValid(error)) return false;
  if (!(rate_accuracy >= 0 && rate_accuracy < 0.1)) {
    if (error) *error = "[table] rate_accuracy must be in [0, 0.1) (relative 1 sigma)";
    return false;
  }
  SensorClass c;
  if (!SensorClassByName(sensor_class, &c)) {
    if (error) *error = "unknown sensor class '" + sensor_class + "' (industrial, consumer)";
    return false;
  }
  // Where only a positive value means anything, a zero is refused (a negative one is the class's).
  for (const auto& [name, value] : {std::pair<const char*, double>{"bias_tau_s", bias_tau_s},
                                    {"warmup_tau_s", warmup_tau_s},
                                    {"acc_noise_density", acc_noise_density},
                                    {"acc_bias_instability", acc_bias_instability},
                                    {"mag_noise_rms", mag_noise_rms},
                                    {"mag_bias_instability", mag_bias_instability}}) {
    if (value == 0.0) {
      if (error) *error = fmt::format("[station] {} must be > 0 (or unset: the class's)", name);
      return false;
    }
  }
  const bool free_source = pose_source == PoseSource::kFree;
  if (!thermal.fit.IsValid(error)) {
    if (error) *error = "[thermal] " + *error;
    return false;
  }
  if (!thermal.gate.IsValid(error) || !thermal.soak.IsValid(error)) return false;
  if (!(thermal.max_pose_span_c > 0)) {
    if (error) *error = "[thermal] max_pose_span_c must be > 0 degC";
    return false;
  }
  if (!(free.min_coverage_percent >= 0 && free.min_coverage_percent <= 100)) {
    if (error) *error = "[free] min_coverage_percent must be in [0, 100]";
    return false;
  }
  if (!(free.max_motion_points >= 10 && free.max_motion_points <= 100000)) {
    if (error) *error = "[free] max_motion_points must be in [10, 100000]";
    return false;
  }
  if (!(free.mag_bandwidth_hz >= 0 && std::isfinite(free.mag_bandwidth_hz))) {
    if (error) *error = "[free] mag_bandwidth_hz must be >= 0 (0: not accounted for)";
    return false;
  }
  // A model of the pose source: a free model without poses, a pose model with them.
  auto known = [&](const std::string& m) {
    std::string base;
    if (IsThermalModelName(m, &base)) {
      if (free_source) {
        if (error) {
          *error = fmt::format(
              "'{}' is a calibration over temperature, which needs known poses (pose_source = "
              "\"announced\")",
              m);
        }
        return false;
      }
      const auto model = MakeModel(base, context, error);
      if (!model) return false;
      if (model->gauge_dimension() > 0) {
        if (error) {
          *error = fmt::format(
              "'{}': {} has a gauge, which is not defined over temperature; calibrate mag13@T", m,
              base);
        }
        return false;
      }
      return true;
    }
    if (!free_source) return MakeModel(m, context, error) != nullptr;
    if (MakeFreeModel(m, FreeContext{}, error)) return true;
    if (error && MakeModel(m, context, nullptr)) {
      *error = fmt::format(
          "'{}' needs known poses; with pose_source = \"free\" the models are free models ({})", m,
          fmt::join(FreeModelNames(), ", "));
    }
    return false;
  };
  // A device has one calibration of each model (one calibrations/DEVICE.MODEL.json).
  auto once = [&](const std::vector<std::string>& list, const std::string& where) {
    for (std::size_t i = 0; i < list.size(); ++i) {
      if (std::find(list.begin(), list.begin() + static_cast<std::ptrdiff_t>(i), list[i]) !=
          list.begin() + static_cast<std::ptrdiff_t>(i)) {
        if (error) {
          *error = fmt::format(
              "{}model '{}' is listed twice: a device has one calibration of "
              "each model",
              where, list[i]);
        }
        return false;
      }
    }
    return true;
  };
  if (models.empty() && !free_source) {
    if (error) *error = "no model to estimate";
    return false;
  }
  for (const auto& m : models) {
    if (!known(m)) return false;
  }
  if (!once(models, "")) return false;
  for (const auto& [name, own] : per_device) {
    if (own.models && own.models->empty() && !free_source) {
      if (error) *error = "device '" + name + "': no model to estimate";
      return false;
    }
    for (const auto& m : own.models.value_or(std::vector<std::string>{})) {
      if (!known(m)) return false;
    }
    if (own.models && !once(*own.models, "device '" + name + "': ")) return false;
    if (own.gate && !own.gate->IsValid(error)) return false;
  }
  return true;
}

SensorClass StationOptions::ResolvedSensorClass() const {
  SensorClass c;
  if (!SensorClassByName(sensor_class, &c)) c = IndustrialClass();
  const std::pair<double, double*> prior[] = {{bias_tau_s, &c.bias_tau_s},
                                              {warmup_in_instabilities, &c.warmup_in_instabilities},
                                              {warmup_tau_s, &c.warmup_tau_s},
                                              {acc_noise_density, &c.acc_noise_density},
                                              {acc_bias_instability, &c.acc_bias_instability},
                                              {mag_noise_rms, &c.mag_noise_rms},
                                              {mag_bias_instability, &c.mag_bias_instability},
                                              {acc_random_walk, &c.acc_random_walk},
                                              {mag_random_walk, &c.mag_random_walk}};
  for (const auto& [value, field] : prior) {
    if (value >= 0) *field = value;
  }
  return c;
}

const char* ToString(PoseSource source) {
  return source == PoseSource::kFree ? "free" : "announced";
}

bool ParsePoseSource(const std::string& text, PoseSource* out) {
  if (text == "announced") {
    *out = PoseSource::kAnnounced;
  } else if (text == "free") {
    *out = PoseSource::kFree;
  } else {
    return false;
  }
  return true;
}

}  // namespace turncal::daemon
