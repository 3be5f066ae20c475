#pragma once
// Tests' helpers for the free pose source's results (RESULT model entries): a fresh temporary
// folder, and every parameter of a free model within 4 sigma of the simulated sensor's truth at
// the result's bias window (host time, the capture's offset taken off).

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "core/modeling/free_model.h"
#include "protocol/calibration_json.h"
#include "sim/capture.h"
#include "sim/free_truth.h"

namespace turncal {

// TempDir()/STEM_PID, emptied and created.
inline std::string FreshTempDir(const std::string& stem) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::path(::testing::TempDir()) / (stem + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

// The result's bias window on the session's clock (host time less the capture's offset).
inline std::optional<TimeWindow> SessionBiasWindow(const sim::SimCapture& capture,
                                                   const nlohmann::json& m) {
  TimeWindow host;
  if (!m.contains("bias_window") || !protocol::ParseTimeWindow(m["bias_window"], &host)) {
    return std::nullopt;
  }
  const double offset_s = static_cast<double>(capture.offset_ns) * 1e-9;
  return TimeWindow{host.t0_s - offset_s, host.t1_s - offset_s};
}

// Every parameter of `m` (a RESULT model entry of free model `name`) within 4 sigma of the truth.
inline void ExpectFreeNearTruth(const sim::SimCapture& capture, const std::string& name,
                                const nlohmann::json& m, const FreeContext& context) {
  Eigen::VectorXd truth;
  std::string error;
  ASSERT_TRUE(sim::FreeTruth(capture, name, context, SessionBiasWindow(capture, m), &truth, &error))
      << error;
  auto model = MakeFreeModel(name, context, &error);
  ASSERT_TRUE(model) << error;
  for (int i = 0; i < model->num_parameters(); ++i) {
    const std::string& p = model->parameters()[static_cast<std::size_t>(i)].name;
    const double value = m["params"][p]["value"].get<double>();
    const double sigma = m["params"][p]["sigma"].get<double>();
    EXPECT_LT(std::abs(value - truth[i]), 4 * sigma)
        << name << " " << p << ": " << value << " truth " << truth[i] << " sigma " << sigma;
  }
}

}  // namespace turncal
