// The station pipeline on a capture (`turncald --replay FILE --once`): bytes -> decoders ->
// sequencer -> calibrators -> observability and gate -> result. On a simulated 36-pose session
// of each protocol family the published estimates are within 4 sigma of the simulator's truth
// and the gate passes.

#include "daemon/station.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>

#include "daemon/replay_once.h"
#include "tools/sim_capture.h"

namespace turncal {
namespace {

std::string WriteCapture(const tools::SimCapture& c, const std::string& stem) {
  const std::string path = ::testing::TempDir() + stem + "_" + std::to_string(::getpid()) + ".tcap";
  std::string error;
  auto writer = drivers::CaptureWriter::Create(path, c.header, &error);
  EXPECT_TRUE(writer) << error;
  for (const auto& r : c.records)
    EXPECT_TRUE(writer->Append(r.type, r.device, r.t_ns, r.payload, &error));
  EXPECT_TRUE(writer->Close(&error)) << error;
  return path;
}

class StationReplay : public ::testing::TestWithParam<drivers::Protocol> {};

TEST_P(StationReplay, EstimatesFromBytesAreWithinFourSigmaOfTheTruth) {
  tools::SimCaptureOptions o;
  o.protocol = GetParam();
  o.session.seed = 9;
  tools::SimCapture c;
  std::string error;
  ASSERT_TRUE(tools::BuildSimCapture(o, &c, &error)) << error;
  const std::string path = WriteCapture(c, "station");
  const std::string result_path = path + ".result.json";
  daemon::ReplayOnceOutcome outcome;
  int active = 0;
  ASSERT_TRUE(daemon::ReplayOnce(
      path, daemon::StationOptions{}, result_path,
      [&](const nlohmann::json& e) { active += e["class"] == "CALIBRATION_ACTIVE"; }, &outcome,
      &error))
      << error;
  std::ifstream in(result_path);
  const nlohmann::json result = nlohmann::json::parse(in);
  EXPECT_EQ(result, outcome.result);
  EXPECT_EQ(result["class"], "RESULT");
  const auto& dev = result["devices"]["imu"];
  EXPECT_EQ(dev["poses"], 36);
  EXPECT_EQ(dev["rejected"], 0);
  EXPECT_GT(active, 0);
  const Eigen::Vector3d acc_wander = c.session.EffectiveAccBiasOffset();
  const Eigen::Vector3d mag_wander = c.session.EffectiveMagBiasOffset();
  for (const std::string name : {"accel13", "mag13"}) {
    const auto& m = dev["models"][name];
    EXPECT_TRUE(m["gate"]["pass"].get<bool>()) << m["gate"].dump();
    EXPECT_EQ(m["rank"], 13);
    auto model = MakeModel(name, ModelContext{}, &error);
    const Eigen::VectorXd& truth = name == "accel13" ? c.session.accel_truth : c.session.mag_truth;
    const Eigen::Vector3d& wander = name == "accel13" ? acc_wander : mag_wander;
    double worst = 0;
    for (int i = 0; i < model->num_parameters(); ++i) {
      const std::string& p = model->parameters()[static_cast<std::size_t>(i)].name;
      double t = truth[i];
      if (p == "bx" || p == "by" || p == "bz") t += wander[p[1] - 'x'];
      const double value = m["params"][p]["value"];
      const double sigma = m["params"][p]["sigma"];
      EXPECT_NEAR(value, t, 4 * sigma) << name << " " << p;
      worst = std::max(worst, std::abs(value - t) / sigma);
    }
    std::printf("%s %s: largest |error| %.2f sigma\n", drivers::ToString(GetParam()), name.c_str(),
                worst);
  }
  std::remove(path.c_str());
  std::remove(result_path.c_str());
}

INSTANTIATE_TEST_SUITE_P(Protocols, StationReplay,
                         ::testing::Values(drivers::Protocol::kMip, drivers::Protocol::kXbus),
                         [](const ::testing::TestParamInfo<drivers::Protocol>& p) {
                           return std::string(drivers::ToString(p.param));
                         });

}  // namespace
}  // namespace turncal
