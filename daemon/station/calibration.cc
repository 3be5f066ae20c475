#include "daemon/station/calibration.h"

#include "daemon/station/free_pipeline.h"
#include "daemon/station/pose_calibrations.h"
#include "daemon/station/station.h"

namespace turncal::daemon {

const std::optional<Eigen::Vector3d>& RawTriad(const Sample& sample, int triad) {
  return triad == kTriadAcc ? sample.acc_mps2 : triad == kTriadGyr ? sample.gyr_radps : sample.mag;
}

Calibration* CalibrationSet::Find(const std::string& name) {
  for (std::size_t i = 0; i < size(); ++i) {
    if (at(i).name() == name) return &at(i);
  }
  return nullptr;
}

const Calibration* CalibrationSet::Find(const std::string& name) const {
  for (std::size_t i = 0; i < size(); ++i) {
    if (at(i).name() == name) return &at(i);
  }
  return nullptr;
}

std::unique_ptr<CalibrationSet> MakeCalibrationSet(const std::vector<std::string>& models,
                                                   const StationOptions& options,
                                                   const SensorClass& sensor,
                                                   const GateOptions& gate) {
  if (options.pose_source == PoseSource::kFree) {
    return std::make_unique<FreeCalibrations>(models, options, sensor, gate);
  }
  return std::make_unique<PoseCalibrations>(models, options, sensor);
}

}  // namespace turncal::daemon
