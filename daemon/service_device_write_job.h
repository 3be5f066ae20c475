#pragma once
// A write into a device under way (daemon/service_device_write.cc starts it,
// daemon/service_device_verify.cc ends it): what was asked, the plan, the steps, the windows of
// the device's output before and after, and the history entry being built.

#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "daemon/device_write.h"
#include "daemon/service.h"
#include "daemon/socket_server.h"
#include "drivers/mip/mip_stored_write.h"
#include "protocol/messages.h"

namespace turncal::daemon {

struct Service::DeviceWriteJob {
  std::weak_ptr<ClientSession> client;
  nlohmann::json id;
  protocol::DeviceWriteArgs args;
  nlohmann::json plan;  // as shown to the client
  std::vector<drivers::mip::StoredWriteStep> steps;
  bool save = false;
  std::string serial;
  int version = 0;
  StoredCalibration device_before;  // what the device holds now
  StoredCalibration device_after;   // what it holds once written
  StoredCalibration as_if;          // the stored values the station's calibrations see
  Eigen::VectorXd theta;            // the calibration written (a verification at a pose uses it)
  Eigen::MatrixXd covariance;
  // kStarting: the window before is full and the write is posted to the loop (it cannot start
  // inside the decoder's sample callback: the write ends that decoder).
  enum class Phase { kBefore, kStarting, kWriting, kAfter } phase = Phase::kBefore;
  OutputWindow before, after;
  int window = 20;
  std::int64_t phase_started_ns = 0;
  WriteAllowance allowance;  // the corrected output's sigma (set before the write), the wander
  nlohmann::json entry;      // the history entry
};

}  // namespace turncal::daemon
