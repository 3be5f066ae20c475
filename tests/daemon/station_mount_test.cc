// A unit on a fixture (issue 38): its pose models take its slot's mount, so a unit mounted at 90
// degrees is calibrated in its own case frame with small mounting angles; a unit that does not sit
// as configured is named from its first poses with the rotation and the mount that would fit, its
// calibrations are held, and once the configuration is fixed the poses already captured (the
// journal) give its calibration.

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "core/frames/mount.h"
#include "daemon/station/replay_once.h"
#include "daemon/station/station.h"
#include "sim/capture.h"
#include "tests/daemon/sim_replay.h"

namespace turncal {
namespace {

// Every parameter of `name` within 4 sigma of the truth (the biases' over the last pose).
void ExpectWithinFourSigma(const nlohmann::json& m, const std::string& name,
                           const sim::SimCapture& c) {
  std::string error;
  ModelContext context;
  context.mounting = c.mount;
  auto model = MakeModel(name, context, &error);
  ASSERT_TRUE(model) << error;
  const Eigen::VectorXd& truth = name == "accel13" ? c.session.accel_truth : c.session.mag_truth;
  const Eigen::Vector3d wander =
      name == "accel13" ? c.session.LastPoseAccBiasOffset() : c.session.LastPoseMagBiasOffset();
  for (int i = 0; i < model->num_parameters(); ++i) {
    const std::string& p = model->parameters()[static_cast<std::size_t>(i)].name;
    double t = truth[i];
    if (p == "bx" || p == "by" || p == "bz") t += wander[p[1] - 'x'];
    EXPECT_NEAR(m["params"][p]["value"].get<double>(), t, 4 * m["params"][p]["sigma"].get<double>())
        << name << " " << p;
  }
}

sim::SimCapture MountedCapture(const Mat3<double>& mount) {
  sim::SimCaptureOptions o;
  o.protocol = drivers::Protocol::kMip;
  o.mount = mount;
  o.session.seed = 10;
  sim::SimCapture c;
  std::string error;
  EXPECT_TRUE(sim::BuildSimCapture(o, &c, &error)) << error;
  return c;
}

daemon::StationOptions WithMount(const std::optional<Mat3<double>>& mount, const std::string& dir) {
  daemon::StationOptions so;
  so.state_dir = dir;
  daemon::DeviceModelOptions own;
  own.mount = mount;
  own.slot = "3";
  so.per_device["imu"] = own;
  return so;
}

TEST(StationMount, AUnitMountedAt90DegreesIsCalibratedInItsOwnCaseFrame) {
  Mat3<double> mount;
  ASSERT_TRUE(ParseMountAxes("-y+x+z", &mount, nullptr));
  const sim::SimCapture c = MountedCapture(mount);
  const std::string path = WriteSimCaptureFile(c, "mount_ok");
  std::vector<nlohmann::json> events;
  daemon::ReplayOnceOutcome outcome;
  std::string error;
  ASSERT_TRUE(daemon::ReplayOnce(
      path, WithMount(mount, ""), "", [&](const nlohmann::json& e) { events.push_back(e); },
      &outcome, &error))
      << error;
  const nlohmann::json& dev = outcome.result["devices"]["imu"];
  EXPECT_EQ(dev["poses"], 36);
  for (const auto& e : events) EXPECT_NE(e["class"], "MOUNT") << e.dump();
  EXPECT_EQ(dev["mount"]["mount"], "\"-y+x+z\"");
  EXPECT_EQ(dev["mount"]["slot"], "3");
  EXPECT_TRUE(dev["mount"]["check"]["ok"].get<bool>());
  EXPECT_TRUE(dev["mount"]["check"]["determined"].get<bool>());
  EXPECT_EQ(dev["mount"]["check"]["rotation_deg"], 0.0);
  for (const std::string name : {"accel13", "mag13"}) {
    const auto& m = dev["models"][name];
    EXPECT_TRUE(m["gate"]["pass"].get<bool>()) << name << m["gate"].dump();
    EXPECT_GT(m["active_version"].get<int>(), 0) << name;
    ExpectWithinFourSigma(m, name, c);
  }
  // The mounting angles are the small error about the slot's mount (the class's: ~0.1 deg).
  for (const char* eps : {"eps_x", "eps_y", "eps_z"}) {
    EXPECT_LT(std::abs(dev["models"]["accel13"]["params"][eps]["value"].get<double>()), 0.02);
  }
  // The batch of one: passed, with the time from its first pose to its last gate (within the
  // session's span), which is the batch's time to its last gate.
  const nlohmann::json& batch = outcome.result["batch"];
  ASSERT_EQ(batch["units"].size(), 1u) << batch;
  EXPECT_EQ(batch["units"][0]["state"], "passed") << batch;
  EXPECT_EQ(batch["units"][0]["slot"], "3");
  const double span_s = 1e-9 * static_cast<double>(c.records.back().t_ns - c.records.front().t_ns);
  EXPECT_GT(batch["units"][0]["seconds"].get<double>(), 0.0);
  EXPECT_LE(batch["units"][0]["seconds"].get<double>(), span_s + 1e-6);
  EXPECT_EQ(batch["seconds_to_last_gate"], batch["units"][0]["seconds"]);
  // Every activation names the batch.
  int named = 0, activations = 0;
  for (const auto& e : events) {
    if (e["class"] != "CALIBRATION_ACTIVE") continue;
    ++activations;
    named += e["batch"] == batch["id"];
  }
  EXPECT_GT(activations, 0);
  EXPECT_EQ(named, activations);
  std::remove(path.c_str());
}

TEST(StationMount, AWrongSlotIsNamedHeldAndCalibratedFromItsPosesOnceFixed) {
  Mat3<double> mount;
  ASSERT_TRUE(ParseMountAxes("-y+x+z", &mount, nullptr));
  const sim::SimCapture c = MountedCapture(mount);
  const std::string path = WriteSimCaptureFile(c, "mount_wrong");
  const std::string dir = ::testing::TempDir() + "mount_state_" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  // Configured as the identity: the unit sits rotated 90 deg about its -z.
  std::vector<nlohmann::json> events;
  daemon::ReplayOnceOutcome outcome;
  std::string error;
  ASSERT_TRUE(daemon::ReplayOnce(
      path, WithMount(std::nullopt, dir), "", [&](const nlohmann::json& e) { events.push_back(e); },
      &outcome, &error))
      << error;
  std::vector<nlohmann::json> mount_events;
  std::vector<int> captured_before;
  int active = 0, captured = 0;
  for (const auto& e : events) {
    if (e["class"] == "POSE_CAPTURED") ++captured;
    active += e["class"] == "CALIBRATION_ACTIVE";
    if (e["class"] != "MOUNT") continue;
    mount_events.push_back(e);
    captured_before.push_back(captured);
    EXPECT_EQ(e["device"], "imu");
    EXPECT_FALSE(e["check"]["ok"].get<bool>());
  }
  // Named at the first pose (its gravity 71 deg off, the rotation not yet known), then, at the
  // first pose whose gravity is in another direction of the case (the default session's third),
  // with the rotation and the mount that fits; the verdict does not change after.
  ASSERT_EQ(mount_events.size(), 2u);
  EXPECT_EQ(captured_before[0], 1);
  EXPECT_EQ(captured_before[1], 3);
  EXPECT_NE(mount_events[0]["message"].get<std::string>().find(
                "slot 3 does not sit as its mount says: gravity is 71 deg from"),
            std::string::npos)
      << mount_events[0]["message"];
  const std::string message = mount_events[1]["message"];
  EXPECT_NE(message.find("slot 3 looks rotated 90 deg about its -z"), std::string::npos) << message;
  EXPECT_NE(message.find("mount = \"-y+x+z\""), std::string::npos) << message;
  EXPECT_EQ(active, 0);
  const nlohmann::json& dev = outcome.result["devices"]["imu"];
  EXPECT_FALSE(dev["mount"]["check"]["ok"].get<bool>());
  EXPECT_EQ(dev["mount"]["check"]["observed_mount"], "\"-y+x+z\"");
  EXPECT_EQ(dev["models"]["accel13"]["active_version"], 0);
  EXPECT_EQ(outcome.result["batch"]["units"][0]["state"], "held");
  EXPECT_NE(outcome.result["batch"]["units"][0]["why"].get<std::string>().find(
                "slot 3 looks rotated 90 deg about its -z"),
            std::string::npos);

  // The operator fixes the configuration and reloads: the journal's 36 poses give the
  // calibration.
  std::vector<nlohmann::json> resumed;
  daemon::Station station({"imu"}, WithMount(mount, dir),
                          [&](const nlohmann::json& e) { resumed.push_back(e); });
  const nlohmann::json result = station.Result();
  int resumed_active = 0;
  for (const auto& e : resumed) {
    EXPECT_NE(e["class"], "MOUNT") << e.dump();
    resumed_active += e["class"] == "CALIBRATION_ACTIVE";
    if (e["class"] == "SESSION_RESUMED") {
      EXPECT_EQ(e["poses"], 36);
    }
  }
  EXPECT_EQ(resumed_active, 2);
  // The same batch (the state directory's batch.json), now passed.
  EXPECT_EQ(result["batch"]["id"], outcome.result["batch"]["id"]);
  EXPECT_EQ(result["batch"]["units"][0]["state"], "passed") << result["batch"];
  const nlohmann::json& fixed = result["devices"]["imu"];
  EXPECT_TRUE(fixed["mount"]["check"]["ok"].get<bool>());
  for (const std::string name : {"accel13", "mag13"}) {
    EXPECT_EQ(fixed["models"][name]["active_version"], 1) << name;
    ExpectWithinFourSigma(fixed["models"][name], name, c);
  }
  std::filesystem::remove_all(dir);
  std::remove(path.c_str());
}

}  // namespace
}  // namespace turncal

namespace turncal {
namespace {

// Issue 38: the next pose for the whole fixture. Two units on one table: "imu" has its session
// (36 poses, its gates pass) and "imu2" none yet. The batch plans for imu2 alone -- a unit that
// passed does not hold the others back -- and before any pose it plans for both, each model
// named with its unit.
TEST(StationBatch, TheNextPoseIsPlannedForEveryUnitStillShortOfAGate) {
  Mat3<double> mount;
  ASSERT_TRUE(ParseMountAxes("-y+x+z", &mount, nullptr));
  const sim::SimCapture c = MountedCapture(Mat3<double>::Identity());
  daemon::StationOptions so;
  so.per_device["imu2"].mount = mount;
  so.per_device["imu2"].slot = "2";
  so.fixture = "two";
  daemon::Station station({"imu", "imu2"}, so, nullptr);
  const nlohmann::json before = station.NextPoseBatch();
  ASSERT_TRUE(before["ok"].get<bool>()) << before.dump();
  EXPECT_EQ(before["batch"]["planned"], 2);
  EXPECT_EQ(before["batch"]["fixture"], "two");
  ASSERT_EQ(before["models"].size(), 4u);
  EXPECT_EQ(before["models"][0]["device"], "imu");
  EXPECT_EQ(before["models"][3]["device"], "imu2");
  // Two units in different mounts need at least the poses one needs.
  const nlohmann::json one = station.NextPose("imu");
  ASSERT_TRUE(one["ok"].get<bool>());
  EXPECT_GE(before["poses_to_gate"].get<int>(), one["poses_to_gate"].get<int>());

  const std::string path = WriteSimCaptureFile(c, "batch");
  drivers::CaptureReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(path, &error)) << error;
  daemon::ReplayStats stats;
  ASSERT_TRUE(daemon::ReplayInto(&reader, &station, true, {}, &stats, &error)) << error;
  const nlohmann::json after = station.NextPoseBatch();
  ASSERT_TRUE(after["ok"].get<bool>()) << after.dump();
  EXPECT_EQ(after["batch"]["planned"], 1);
  EXPECT_EQ(after["batch"]["units"][0]["state"], "passed");
  EXPECT_EQ(after["batch"]["units"][0]["poses"], 36);
  EXPECT_EQ(after["batch"]["units"][1]["state"], "planned");
  EXPECT_EQ(after["batch"]["units"][1]["slot"], "2");
  ASSERT_EQ(after["models"].size(), 2u);
  for (const auto& m : after["models"]) EXPECT_EQ(m["device"], "imu2");
  std::remove(path.c_str());
}

}  // namespace
}  // namespace turncal

namespace turncal {
namespace {

// Issue 38's bad input: two units of the batch report one serial. The later one is named, its
// calibrations are held (they would be filed under the other unit), and a serial of its own
// clears it.
TEST(StationBatch, TwoUnitsWithOneSerialAreNamedAndTheLaterIsHeld) {
  const sim::SimCapture c = MountedCapture(Mat3<double>::Identity());
  std::vector<nlohmann::json> events;
  daemon::Station station({"imu", "imu2"}, daemon::StationOptions{},
                          [&](const nlohmann::json& e) { events.push_back(e); });
  // The session's batch: no state directory, no [fixture] batch: "batch-UTCTIME", two units.
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0]["class"], "BATCH");
  EXPECT_EQ(events[0]["id"].get<std::string>().rfind("batch-", 0), 0u) << events[0];
  ASSERT_EQ(events[0]["units"].size(), 2u);
  EXPECT_EQ(events[0]["units"][1]["state"], "waiting");
  events.clear();
  station.SetDeviceIdentity(1, {{"protocol", "mip"}, {"serial", "SIM0001"}});
  station.SetDeviceIdentity(0, {{"protocol", "mip"}, {"serial", "SIM0001"}});
  // The error, and the batch with imu held.
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[1]["class"], "BATCH");
  EXPECT_EQ(events[1]["units"][0]["state"], "held");
  EXPECT_EQ(events[0]["class"], "ERROR");
  EXPECT_EQ(events[0]["device"], "imu");
  EXPECT_NE(events[0]["message"].get<std::string>().find(
                "imu reports serial SIM0001, as imu2 does: two units with one serial"),
            std::string::npos)
      << events[0]["message"];
  EXPECT_EQ(station.Status(0)["duplicate_serial_of"], "imu2");
  EXPECT_TRUE(station.Status(1)["duplicate_serial_of"].is_null());

  const std::string path = WriteSimCaptureFile(c, "dup_serial");
  drivers::CaptureReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(path, &error)) << error;
  daemon::ReplayStats stats;
  ASSERT_TRUE(daemon::ReplayInto(&reader, &station, true, {}, &stats, &error)) << error;
  int active = 0;
  for (const auto& e : events) active += e["class"] == "CALIBRATION_ACTIVE";
  EXPECT_EQ(active, 0);
  const nlohmann::json result = station.Result();
  EXPECT_TRUE(result["devices"]["imu"]["models"]["accel13"]["gate"]["pass"].get<bool>());
  EXPECT_EQ(result["devices"]["imu"]["models"]["accel13"]["active_version"], 0);
  // The batch slot by slot: imu held and why; imu2 (the capture has no stream of it) waits.
  const nlohmann::json& batch = result["batch"];
  ASSERT_EQ(batch["units"].size(), 2u) << batch;
  EXPECT_EQ(batch["units"][0]["state"], "held") << batch;
  EXPECT_EQ(batch["units"][0]["why"], "reports the serial of imu2");
  EXPECT_EQ(batch["units"][1]["state"], "waiting") << batch;
  EXPECT_EQ(batch["units"][1]["why"], "no pose yet");
  EXPECT_EQ(batch["units"][1]["serial"], "SIM0001");
  EXPECT_EQ(batch["passed"], 0);
  EXPECT_EQ(batch["held"], 1);
  EXPECT_EQ(batch["waiting"], 1);
  EXPECT_TRUE(batch["seconds_to_last_gate"].is_null());
  // The unit answers with its own serial (the cable moved): the conflict is gone.
  station.SetDeviceIdentity(0, {{"protocol", "mip"}, {"serial", "SIM0003"}});
  EXPECT_TRUE(station.Status(0)["duplicate_serial_of"].is_null());
  std::remove(path.c_str());
}

}  // namespace
}  // namespace turncal
