#pragma once
// The lines of a sample stream (docs/protocol.md "watch"): SAMPLE, a device's output as it sent
// it, and CORRECTED, the output corrected by the active calibrations (with their 1 sigma and, on
// request, the raw sample inside). One JSON object a line, ending in a newline.
//
// A station streams every sample of up to 8 devices at 1000 Hz to every subscriber, so the lines
// are built with std::to_chars into a buffer the caller keeps, not through a JSON library.

#include <Eigen/Core>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/sequencing/sample.h"

namespace turncal::protocol {

// A sample corrected by a device's active calibrations (daemon/station/station.h Correct).
struct CorrectedSample {
  std::optional<Eigen::Vector3d> acc_mps2, mag, gyr_radps;
  // With sigma: the 1 sigma of each output axis from the calibration's covariance
  // (J Sigma J^T, J = d correction / d theta by central differences; noise not included).
  std::optional<Eigen::Vector3d> acc_sigma, mag_sigma, gyr_sigma;
  const char* acc_frame = nullptr;  // "case" or "table"
  const char* mag_frame = nullptr;
  const char* gyr_frame = nullptr;
  std::vector<std::pair<std::string, int>> versions;  // model, active version
  // The sample on the sensor clock of pose records (t_sensor_start, t_sensor_end), when known.
  std::optional<double> t_sensor_s;
  // A calibration over temperature that corrected this sample at another temperature than the
  // sample's: model, "below_range" | "above_range" | "no_temperature" (docs/THERMAL.md).
  std::vector<std::pair<std::string, const char*>> temperature_flags;
};

// Appends {"class":"SAMPLE","device":...,"t_host_ns":...,"t_device":...,"counter":...,"acc":[...],
// "gyr":[...],"mag":[...],"temp":...,"flags":[...]} and a newline. Measured values are the
// shortest text that reads back to the same 32-bit float.
void AppendSampleLine(std::string* out, const Sample& sample);

// Appends {"class":"CORRECTED",...,"versions":{...}} and a newline: `corrected`'s triads and
// frames, their sigma with `with_sigma`, the device's own gyroscope where no model corrects it,
// and with `with_raw` the SAMPLE object of `sample` as "raw".
void AppendCorrectedLine(std::string* out, const Sample& sample, const CorrectedSample& corrected,
                         bool with_raw, bool with_sigma);

}  // namespace turncal::protocol
