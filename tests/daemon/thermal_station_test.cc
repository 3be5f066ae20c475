// Calibration over temperature through the station (issue 36): a simulated device in a climate
// chamber as bytes (sim/capture.h with a chamber, exactly what `turncal sim --chamber` writes),
// replayed as `turncald --replay --once` replays it with "accel13@T" and "mag13@T" configured;
// the estimates at temperatures the poses did not visit against the truth, the gate over the range,
// the stored document applied again by a restarted station, and each live sample corrected at its
// own temperature (clamped and flagged outside the range).

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "daemon/state/persistence.h"
#include "daemon/station/replay_once.h"
#include "daemon/station/station.h"
#include "daemon/station/thermal_pipeline.h"
#include "protocol/thermal_json.h"
#include "sim/capture.h"
#include "tests/daemon/sim_replay.h"

namespace turncal {
namespace {

namespace fs = std::filesystem;

std::string TempDir(const std::string& stem) {
  const fs::path dir = fs::path(::testing::TempDir()) / (stem + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

// A consumer-grade device on a table cycling the 36 default poses through a 0 -> 40 degC ramp at
// 4 degC/min (144 poses of 4 s; the die lags the air by 5 minutes and reports 0.01 degC steps).
sim::SimCapture RampSession() {
  sim::SimCaptureOptions o;
  o.protocol = drivers::Protocol::kMip;
  o.accel_model = "accel13";
  o.mag_model = "mag13";
  o.poses = DefaultSessionPoses();
  SensorClassByName("consumer", &o.session.sensor);
  o.session.rate_hz = 100;
  o.session.dwell_s = 4.0;
  o.session.seed = 4;
  std::string error;
  ChamberProfile chamber;
  EXPECT_TRUE(ChamberProfile::Parse("0; ramp 40 4 300", &chamber, &error)) << error;
  o.session.chamber = chamber;
  o.session.die.quantum_c = 0.01;
  o.session.repeat_poses_through_chamber = true;
  sim::SimCapture c;
  EXPECT_TRUE(sim::BuildSimCapture(o, &c, &error)) << error;
  return c;
}

daemon::StationOptions ThermalOptions(const std::string& state_dir) {
  daemon::StationOptions options;
  options.models = {"accel13@T", "mag13@T"};
  options.sensor_class = "consumer";
  GateDefaultsForClass("consumer", &options.gate);
  options.state_dir = state_dir;
  return options;
}

// The truth a calibration over temperature estimates: the simulator's polynomials, the biases plus
// their wander over the latest pose (the bias window's pose).
Eigen::VectorXd TruthAt(const sim::SimCapture& c, bool accel, double temp_c) {
  const ThermalTruth& t = accel ? *c.session.accel_thermal : *c.session.mag_thermal;
  Eigen::VectorXd theta = t.ThetaAt(temp_c);
  const SessionPoseEvent& last = c.session.events.back();
  theta.tail<3>() += accel ? last.acc_wander_mean : last.mag_wander_mean;  // bx by bz are last
  return theta;
}

TEST(ThermalStation, ARampCalibratesEveryParameterOverTemperatureThroughThePipeline) {
  const sim::SimCapture capture = RampSession();
  ASSERT_TRUE(capture.session.accel_thermal && capture.session.mag_thermal);
  const std::string path = WriteSimCaptureFile(capture, "thermal_station");
  const std::string state = TempDir("thermal_station_state");
  const daemon::StationOptions options = ThermalOptions(state);
  std::string error;
  ASSERT_TRUE(options.IsValid(&error)) << error;
  int estimates = 0;
  daemon::ReplayOnceOutcome outcome;
  ASSERT_TRUE(daemon::ReplayOnce(
      path, options, "", [&](const nlohmann::json& e) { estimates += e["class"] == "ESTIMATE"; },
      &outcome, &error))
      << error;
  const nlohmann::json& d = outcome.result["devices"]["imu"];
  ASSERT_EQ(d["poses"].get<int>(), 144) << d.dump();
  // After the first 30 poses the fit is repeated as the poses grow by a tenth, and at the end.
  EXPECT_LT(estimates, 2 * 60);
  for (const char* name : {"accel13@T", "mag13@T"}) {
    SCOPED_TRACE(name);
    const nlohmann::json& m = d["models"][name];
    ASSERT_TRUE(m["ok"].get<bool>()) << m.dump();
    EXPECT_EQ(m["poses"].get<int>(), 144);  // every pose, the last ones included
    const nlohmann::json& t = m["temperature"];
    // The die lags the air: the range is what the die reported, not the chamber's 0 .. 40.
    EXPECT_NEAR(t["t_min_c"].get<double>(), 0.0, 1.0);
    EXPECT_GT(t["t_max_c"].get<double>(), 35.0);
    EXPECT_LT(t["t_max_c"].get<double>(), 40.0);
    EXPECT_GT(t["p_value"].get<double>(), 1e-3);
  }
  // Consumer biases drift by more than their 2 mg tolerance over the ramp's ends: the gate names
  // where (the magnetometer passes and is published).
  const nlohmann::json& acc_gate = d["models"]["accel13@T"]["gate"];
  if (!acc_gate["pass"].get<bool>()) {
    ASSERT_FALSE(acc_gate["reasons"].empty());
    EXPECT_NE(acc_gate["reasons"][0].get<std::string>().find("degC"), std::string::npos)
        << acc_gate.dump();
  }
  EXPECT_TRUE(d["models"]["mag13@T"]["gate"]["pass"].get<bool>()) << d["models"].dump();

  // Every parameter at temperatures between those the poses visited, within 4 sigma of the truth.
  for (bool accel : {true, false}) {
    const std::string name = accel ? "accel13@T" : "mag13@T";
    SCOPED_TRACE(name);
    auto model = MakeModel(accel ? "accel13" : "mag13", ModelContext{}, &error);
    ThermalEstimate e;
    nlohmann::json doc = d["models"][name];
    ASSERT_TRUE(protocol::ReadThermalEstimate(*model, doc, &e, &error)) << error;
    for (double temp_c : {7.3, 18.1, 29.6}) {
      const Eigen::VectorXd truth = TruthAt(capture, accel, temp_c);
      const Eigen::VectorXd theta = e.ThetaAt(temp_c), sigma = e.SigmaAt(temp_c);
      for (int p = 0; p < model->num_parameters(); ++p) {
        EXPECT_LT(std::abs(theta[p] - truth[p]), 4 * sigma[p])
            << model->parameters()[static_cast<std::size_t>(p)].name << " at " << temp_c;
      }
    }
  }

  // A restarted station applies the stored magnetometer calibration; each live sample is corrected
  // with the parameters at its own temperature.
  daemon::Station again({"imu"}, options, [](const nlohmann::json&) {});
  ASSERT_TRUE(again.HasAppliedCalibration(0));
  nlohmann::json stored;
  ASSERT_TRUE(daemon::ReadActiveCalibration(state, "imu", "mag13@T", &stored));
  EXPECT_TRUE(protocol::IsThermalCalibration(stored));
  auto mag = MakeModel("mag13", ModelContext{}, &error);
  ThermalEstimate applied;
  ASSERT_TRUE(protocol::ReadThermalEstimate(*mag, stored, &applied, &error)) << error;
  const TablePose pose = DefaultSessionPoses()[5];
  auto corrected_at = [&](std::optional<double> sample_c, double truth_c,
                          daemon::Station::Corrected* out) {
    const Eigen::VectorXd truth = TruthAt(capture, false, truth_c);
    Sample s;
    s.mag = mag->Predict(truth, pose);
    s.temp_c = sample_c;
    s.t_host_ns = static_cast<std::int64_t>(capture.session.duration_s * 1e9);
    EXPECT_TRUE(again.Correct(0, s, out, true));
    return Eigen::Vector3d(mag->Correct(truth, *s.mag));
  };
  for (double temp_c : {12.4, 26.9}) {
    daemon::Station::Corrected out;
    const Eigen::Vector3d want = corrected_at(temp_c, temp_c, &out);
    ASSERT_TRUE(out.mag && out.mag_sigma);
    EXPECT_TRUE(out.temperature_flags.empty());
    for (int axis = 0; axis < 3; ++axis) {
      EXPECT_LT(std::abs((*out.mag)[axis] - want[axis]), 4 * (*out.mag_sigma)[axis] + 1e-12)
          << "axis " << axis << " at " << temp_c;
    }
  }
  // Above the range: corrected with the parameters at T_max, flagged, counted in status.
  daemon::Station::Corrected hot, edge;
  corrected_at(60.0, 60.0, &hot);
  corrected_at(applied.t_max_c, 60.0, &edge);
  ASSERT_EQ(hot.temperature_flags.size(), 1u);
  EXPECT_EQ(hot.temperature_flags[0].first, "mag13@T");
  EXPECT_STREQ(hot.temperature_flags[0].second, "above_range");
  EXPECT_LT((*hot.mag - *edge.mag).norm(), 1e-12);
  daemon::Station::Corrected cold, unknown;
  corrected_at(-30.0, 0.0, &cold);
  corrected_at(std::nullopt, 20.0, &unknown);
  EXPECT_STREQ(cold.temperature_flags.at(0).second, "below_range");
  EXPECT_STREQ(unknown.temperature_flags.at(0).second, "no_temperature");
  const nlohmann::json status = again.Status(0)["models"]["mag13@T"];
  EXPECT_EQ(status["outside_range"]["above"].get<int>(), 1) << status.dump();
  EXPECT_EQ(status["outside_range"]["below"].get<int>(), 1);
  EXPECT_EQ(status["outside_range"]["no_temperature"].get<int>(), 1);
  std::string line;
  Sample raw;
  raw.mag = Eigen::Vector3d(0.2, 0.0, 0.4);
  raw.temp_c = 60.0;
  protocol::AppendCorrectedLine(&line, raw, hot, false, false);
  EXPECT_NE(line.find(R"("temp_flags":{"mag13@T":"above_range"})"), std::string::npos) << line;
}

TEST(ThermalStation, WhatCannotBeCalibratedOverTemperatureIsRefusedWithTheReason) {
  daemon::StationOptions options;
  std::string error;
  options.models = {"mag22@T"};
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("gauge"), std::string::npos) << error;
  options.models = {"accel13@T"};
  options.pose_source = daemon::PoseSource::kFree;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("known poses"), std::string::npos) << error;
  options.pose_source = daemon::PoseSource::kAnnounced;
  options.thermal.fit.max_order = 9;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("[thermal] max_order"), std::string::npos) << error;
  options.thermal.fit.max_order = 3;
  EXPECT_TRUE(options.IsValid(&error)) << error;

  // A pose without the device's temperature is refused, with the reason; nothing else changes.
  auto m = daemon::MakePoseModel("accel13@T", options, IndustrialClass());
  ASSERT_EQ(m->name(), "accel13@T");
  PoseRecord record;
  record.pose = DefaultSessionPoses()[0];
  TriadStats stats;
  stats.mean = Eigen::Vector3d(0, 0, -9.8);
  stats.covariance = Eigen::Matrix3d::Identity() * 1e-6;
  stats.count = 100;
  record.acc = stats;
  record.t_end_s = 1.0;
  daemon::ModelUpdate job;
  m->AddAndSolve(record, options.gate, &job);
  EXPECT_FALSE(job.added);
  EXPECT_NE(job.error.find("no temperature"), std::string::npos) << job.error;
  // A temperature that jumped within the window: refused too.
  record.temp_c = 25.0;
  record.temp_spread = TemperatureSpread{3.0, 24.9, 125.0};
  m->AddAndSolve(record, options.gate, &job);
  EXPECT_FALSE(job.added);
  EXPECT_NE(job.error.find("or a jump in the temperature channel?"), std::string::npos)
      << job.error;
  record.temp_spread = TemperatureSpread{0.01, 24.98, 25.02};
  m->AddAndSolve(record, options.gate, &job);
  EXPECT_TRUE(job.added) << job.error;
  // One pose at one temperature: no estimate yet, and the gate says why.
  EXPECT_FALSE(job.gate.pass);
  EXPECT_FALSE(job.gate.reasons.empty());
}

}  // namespace
}  // namespace turncal
