// Issue 21 in the station: NEXT_POSE for a device with a gyroscope model plans rate segments
// when the table can hold rates ([table] plan_rates_dps) and counts the moves the sequencer
// integrates; status and RESULT count the moves taken, dropped and refused.

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <string>

#include "core/frames/units.h"
#include "daemon/station/replay_once.h"
#include "daemon/station/station.h"
#include "sim/capture.h"
#include "sim/session_sim.h"
#include "tests/daemon/sim_replay.h"

namespace turncal {
namespace {

// Five static poses, a rate segment, two more static poses: five moves are taken (into poses 2 to
// 5 and 8; none into the pose after the rate segment), the one across the segment is dropped.
// With `end_on_rate_segment` the session stops after the segment.
sim::SimCapture Session(bool end_on_rate_segment) {
  sim::SimCaptureOptions o;
  o.protocol = drivers::Protocol::kMip;
  o.gyro_model = "gyro12";
  o.session.seed = 31;
  std::vector<TablePose> poses = DefaultSessionPoses();
  poses.resize(5);
  poses.push_back(DefaultRateSegments().front());
  if (!end_on_rate_segment) {
    poses.push_back(DefaultSessionPoses()[5]);
    poses.push_back(DefaultSessionPoses()[6]);
  }
  o.poses = poses;
  sim::SimCapture c;
  std::string error;
  EXPECT_TRUE(sim::BuildSimCapture(o, &c, &error)) << error;
  return c;
}

daemon::StationOptions Options() {
  daemon::StationOptions options;
  options.models = {"accel13", "gyro12"};
  options.plan_rates.rates_dps = {100, -100, 30, -30};
  return options;
}

// The station as a live one sees the capture: the input does not end (a replay's end drops the
// move being tracked, which a live station would go on integrating).
class Live final : public daemon::ReplayTarget {
 public:
  explicit Live(daemon::Station* station) : station_(station) {}
  void OnSample(int device, const Sample& sample) override { station_->OnSample(device, sample); }
  bool OnAnnounce(const Announcement& announcement, const std::vector<int>& devices,
                  std::string* error) override {
    return station_->OnAnnounce(announcement, devices, error);
  }
  void OnTick(std::int64_t now_ns) override { station_->OnTick(now_ns); }
  void OnFinish(std::int64_t) override {}

 private:
  daemon::Station* station_;
};

void Replay(const std::string& path, daemon::Station* station) {
  drivers::CaptureReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(path, &error)) << error;
  daemon::ReplayStats stats;
  Live live(station);
  ASSERT_TRUE(daemon::ReplayInto(&reader, &live, true, {}, &stats, &error)) << error;
}

const nlohmann::json& ModelOf(const nlohmann::json& advice, const std::string& name) {
  for (const auto& m : advice["models"]) {
    if (m["model"] == name) return m;
  }
  static const nlohmann::json none;
  ADD_FAILURE() << "no model " << name << " in " << advice.dump();
  return none;
}

TEST(GyroStation, NextPoseCountsTheMovesAndPlansRateSegmentsAndStatusCountsTheMoves) {
  const std::string path = WriteSimCaptureFile(Session(false), "gyro_station");
  daemon::Station station({"imu"}, Options(), {});
  Replay(path, &station);
  // Status: 8 records, 6 moves taken (into poses 2-5 and 8; not into the rate segment nor the
  // pose after it), the one across the rate segment dropped with its reason.
  const nlohmann::json status = station.Status(0);
  EXPECT_EQ(status["poses"], 8) << status.dump();
  const nlohmann::json& moves = status["moves"];
  EXPECT_EQ(moves["enabled"], true);
  EXPECT_EQ(moves["taken"], 5) << moves.dump();
  EXPECT_EQ(moves["dropped"], 1) << moves.dump();
  EXPECT_NE(moves["last_drop"].get<std::string>().find("rate segment"), std::string::npos)
      << moves.dump();
  EXPECT_EQ(status["models"]["gyro12"]["moves"], 5);
  EXPECT_EQ(status["models"]["gyro12"]["moves_refused"], 0);
  EXPECT_EQ(station.Result()["devices"]["imu"]["moves"]["taken"], 5);

  const nlohmann::json advice = station.NextPose("imu");
  ASSERT_TRUE(advice["ok"].get<bool>()) << advice.dump();
  // Both models are planned for; the gyroscope's captured records are its poses, its rate
  // segment and its moves, and the accelerometer gains nothing from a rate segment.
  const nlohmann::json& gyro = ModelOf(advice, "gyro12");
  EXPECT_EQ(gyro["captured"]["poses"], 7) << gyro.dump();
  EXPECT_EQ(gyro["captured"]["rate_segments"], 1);
  EXPECT_EQ(gyro["captured"]["moves"], 5);
  EXPECT_EQ(ModelOf(advice, "accel13")["captured"]["rate_segments"], 0);
  EXPECT_EQ(ModelOf(advice, "accel13")["captured"]["poses"], 7);
  bool rate_planned = false;
  for (const auto& p : advice["plan"]) rate_planned = rate_planned || p.contains("rate_axis");
  EXPECT_TRUE(rate_planned) << advice.dump();
  // The table stands at a captured static pose: a static candidate carries the move into it; a
  // rate segment carries none, and the accelerometer's gain from one is zero.
  for (const auto& c : advice["top"]) {
    if (c["pose"].contains("rate_axis")) {
      EXPECT_FALSE(c["move"].get<bool>());
      EXPECT_EQ(c["model_gains"][0].get<double>(), 0.0);
    } else {
      EXPECT_TRUE(c["move"].get<bool>()) << c.dump();
    }
  }
  std::remove(path.c_str());
}

TEST(GyroStation, AfterARateSegmentNoMoveIsCreditedIntoTheNextPose) {
  const std::string path = WriteSimCaptureFile(Session(true), "gyro_station_rate");
  daemon::Station station({"imu"}, Options(), {});
  Replay(path, &station);
  const nlohmann::json advice = station.NextPose("imu");
  ASSERT_TRUE(advice["ok"].get<bool>()) << advice.dump();
  for (const auto& c : advice["top"]) EXPECT_FALSE(c["move"].get<bool>()) << c.dump();
  std::remove(path.c_str());
}

}  // namespace
}  // namespace turncal
