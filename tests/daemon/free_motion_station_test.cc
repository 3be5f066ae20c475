// Issue 37 in the station: a hand's continuous rotation (no still moment, the magnetometer slower
// than the stream) as a device's bytes runs through the station exactly as `turncald --replay FILE
// --once --pose-source free` runs it. The magnetometer's values in motion are kept, journaled and
// fitted: the ellipsoid within 4 sigma of its truth (sigma from the Fisher information, the bias
// at the estimate's window), gated and activated; the journal holds the values, and a restarted
// station resumes them to the same estimate; [free] motion = false refuses with the reason.

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>

#include "core/analysis/sphere_coverage.h"
#include "daemon/service/config.h"
#include "daemon/state/persistence.h"
#include "daemon/station/free_pipeline.h"
#include "daemon/station/replay_once.h"
#include "protocol/calibration_json.h"
#include "protocol/free_json.h"
#include "sim/capture.h"
#include "sim/free_truth.h"
#include "tests/daemon/free_result_check.h"
#include "tests/daemon/sim_replay.h"

namespace turncal {
namespace {

namespace fs = std::filesystem;

sim::SimCapture Hand(drivers::Protocol protocol, double rate_hz, double mag_rate_hz,
                     const std::string& sensor_class, std::uint64_t seed) {
  sim::SimCaptureOptions o;
  o.protocol = protocol;
  o.accel_model = "accel13";
  o.mag_model = "mag13";
  o.poses.clear();
  EXPECT_TRUE(SensorClassByName(sensor_class, &o.session.sensor));
  o.session.rate_hz = rate_hz;
  o.session.mag_rate_hz = mag_rate_hz;
  o.session.start_s = 0.0;  // no still moment
  sim::HandMotion hand;
  hand.duration_s = 10.0;
  o.session.hand = hand;
  o.session.seed = seed;
  sim::SimCapture c;
  std::string error;
  EXPECT_TRUE(sim::BuildSimCapture(o, &c, &error)) << error;
  return c;
}

daemon::StationOptions MotionOptions(const std::string& state_dir,
                                     const std::string& sensor_class) {
  daemon::Config config;
  daemon::StationOptions options;
  daemon::ApplyPoseSource(daemon::PoseSource::kFree, config, &options);
  options.models = {"magellipsoid"};
  options.sensor_class = sensor_class;
  options.state_dir = state_dir;
  return options;
}

// The ellipsoid within 4 sigma of its truth at the last value's window (within the motion).
void ExpectNearTruth(const sim::SimCapture& capture, const nlohmann::json& m,
                     const FreeContext& context) {
  const std::optional<TimeWindow> window = SessionBiasWindow(capture, m);
  ASSERT_TRUE(window) << m.dump();
  EXPECT_GT(window->t0_s, capture.session.duration_s - 0.1);
  EXPECT_LE(window->t0_s, capture.session.duration_s);
  ExpectFreeNearTruth(capture, "magellipsoid", m, context);
}

struct Replayed {
  daemon::ReplayOnceOutcome outcome;
  int estimates = 0, activations = 0;
};

Replayed Replay(const std::string& path, const daemon::StationOptions& options) {
  Replayed r;
  std::string error;
  EXPECT_TRUE(daemon::ReplayOnce(
      path, options, "",
      [&](const nlohmann::json& e) {
        r.estimates += e["class"] == "ESTIMATE";
        r.activations += e["class"] == "CALIBRATION_ACTIVE";
      },
      &r.outcome, &error))
      << error;
  return r;
}

TEST(FreeMotionStation, AHandRotationCalibratesTheMagnetometerThroughThePipeline) {
  const sim::SimCapture capture = Hand(drivers::Protocol::kMip, 1000, 100, "industrial", 21);
  const std::string path = WriteSimCaptureFile(capture, "free_motion_station");
  const std::string state = FreshTempDir("free_motion_station_state");
  const daemon::StationOptions options = MotionOptions(state, "industrial");
  ASSERT_TRUE(options.IsValid(nullptr));
  const Replayed r = Replay(path, options);
  const nlohmann::json& d = r.outcome.result["devices"]["imu"];
  EXPECT_EQ(d["poses"].get<int>(), 0) << "no still interval in a hand's rotation";
  // The values: one new per magnetometer update (100 Hz of a 1 kHz stream), the rest held.
  const nlohmann::json& motion = d["free"]["motion"];
  EXPECT_EQ(motion["values"].get<int>(), 1000) << motion.dump();
  EXPECT_EQ(motion["held"].get<int>(), 9000);
  // At most [free] max_motion_points (600) of them, evenly spread.
  EXPECT_EQ(motion["points"].get<int>(), options.free.max_motion_points);
  EXPECT_EQ(motion["decimated"].get<int>(), 1000 - options.free.max_motion_points);
  EXPECT_NEAR(motion["rate_hz"].get<double>(), 100.0, 0.1);
  EXPECT_NE(motion["noise_source"].get<std::string>().find("industrial class"), std::string::npos)
      << "never still: the class's noise, said so";
  // Fitted as the values grew (doubling) and at the end; activated once the gate passed.
  EXPECT_GE(r.estimates, 4);
  EXPECT_GE(r.activations, 1);
  const nlohmann::json& m = d["models"]["magellipsoid"];
  ASSERT_TRUE(m["ok"].get<bool>()) << m.dump();
  EXPECT_EQ(m["model"], "magellipsoid") << m["note"];
  EXPECT_TRUE(m["gate"]["pass"].get<bool>()) << m["gate"].dump();
  EXPECT_EQ(m["motion_points"].get<int>(), options.free.max_motion_points);
  SensorClass sensor;
  SensorClassByName("industrial", &sensor);
  const FreeContext context = daemon::FreeContextFor(options, sensor);
  ExpectNearTruth(capture, m, context);
  // chi^2/dof near 1: the class's noise is the simulated sensor's.
  EXPECT_NEAR(m["chi2"].get<double>() / m["dof"].get<double>(), 1.0, 0.2);

  // The journal holds every value, in batches; the stored document the points it fitted.
  std::vector<daemon::JournalEntry> entries;
  int skipped = 0;
  std::string error;
  ASSERT_TRUE(daemon::PoseJournal::Load(state, &entries, &skipped, &error)) << error;
  std::size_t values = 0, batches = 0;
  for (const auto& e : entries) {
    if (e.is_motion()) values += e.motion.size(), ++batches;
  }
  EXPECT_EQ(values, 1000u);
  EXPECT_GE(batches, 5u);
  EXPECT_EQ(skipped, 0);
  nlohmann::json stored;
  ASSERT_TRUE(daemon::ReadActiveCalibration(state, "imu", "magellipsoid", &stored));
  protocol::FreeCalibrationDocument doc;
  ASSERT_TRUE(protocol::ParseFreeCalibration(stored, &doc, &error)) << error;
  EXPECT_EQ(doc.version, m["active_version"].get<int>());
  EXPECT_EQ(doc.intervals.size(), static_cast<std::size_t>(options.free.max_motion_points));
  ASSERT_FALSE(doc.intervals.empty());
  EXPECT_TRUE(doc.intervals.back().in_motion);

  // A restarted station resumes the journal's values to the same estimate, and publishes nothing
  // new for them.
  const std::string empty = WriteSimCaptureFile(
      [&] {
        sim::SimCapture c = capture;
        c.records.erase(c.records.begin() + 1, c.records.end());
        return c;
      }(),
      "free_motion_station_empty");
  const Replayed again = Replay(empty, options);
  const nlohmann::json& m2 = again.outcome.result["devices"]["imu"]["models"]["magellipsoid"];
  ASSERT_TRUE(m2["ok"].get<bool>()) << m2.dump();
  EXPECT_EQ(m2["motion_points"].get<int>(), options.free.max_motion_points);
  EXPECT_EQ(m2["active_version"], m["active_version"]);
  for (const char* p : {"bx", "by", "bz", "s11", "s23"}) {
    EXPECT_NEAR(m2["params"][p]["value"].get<double>(), m["params"][p]["value"].get<double>(), 1e-9)
        << p;
  }
  fs::remove_all(state);
  fs::remove(path);
  fs::remove(empty);
}

// Live guidance (issue 37): while the values arrive the station publishes the magnetometer's
// coverage every half second of the stream -- the 18 x 32 bins, centred by the values' midpoint
// until a fit, then by the latest magnetometer fit -- and the largest region without a value with
// what to do about it. The last event's bins are the final fit's directions of every value (to a
// few bins: it is centred by the fit before the last), and no value lies inside the region it
// names (to a bin's size).
TEST(FreeMotionStation, TheCoverageFillsAsTheValuesArriveAndNamesTheLargestGap) {
  const sim::SimCapture capture = Hand(drivers::Protocol::kMip, 1000, 100, "industrial", 21);
  const std::string path = WriteSimCaptureFile(capture, "free_motion_coverage");
  const std::string state = FreshTempDir("free_motion_coverage_state");
  const daemon::StationOptions options = MotionOptions(state, "industrial");
  std::vector<nlohmann::json> events;
  daemon::ReplayOnceOutcome outcome;
  std::string error;
  ASSERT_TRUE(daemon::ReplayOnce(
      path, options, "",
      [&](const nlohmann::json& e) {
        if (e["class"] == "COVERAGE") events.push_back(e);
      },
      &outcome, &error))
      << error;
  ASSERT_GE(events.size(), 18u)
      << "every half second of a 10-s rotation from 50 values, and at its end";
  int previous_values = 0;
  bool fitted = false;
  for (const auto& e : events) {
    EXPECT_EQ(e["device"], "imu");
    const auto rows = e["rows"].get<std::vector<std::string>>();
    ASSERT_EQ(rows.size(), 18u);
    int marked = 0;
    for (const auto& r : rows) {
      ASSERT_EQ(r.size(), 32u);
      marked += static_cast<int>(std::count(r.begin(), r.end(), '#'));
    }
    EXPECT_EQ(marked, e["filled"].get<int>());
    EXPECT_NEAR(e["fraction"].get<double>(), marked / 576.0, 1e-12);
    EXPECT_GE(e["values"].get<int>(), previous_values);
    previous_values = e["values"].get<int>();
    fitted = fitted || e["centre"] == "the magellipsoid fit";
  }
  EXPECT_EQ(events.front()["centre"], "the values' midpoint (no fit yet)");
  EXPECT_TRUE(fitted);
  const nlohmann::json& last = events.back();
  EXPECT_EQ(last["values"].get<int>(), 1000);

  // The final fit's directions of every journaled value.
  nlohmann::json stored;
  ASSERT_TRUE(daemon::ReadActiveCalibration(state, "imu", "magellipsoid", &stored));
  protocol::FreeCalibrationDocument doc;
  ASSERT_TRUE(protocol::ParseFreeCalibration(stored, &doc, &error)) << error;
  const auto model = MakeFreeModel(doc.model, doc.context, &error);
  ASSERT_TRUE(model) << error;
  std::vector<daemon::JournalEntry> entries;
  int skipped = 0;
  ASSERT_TRUE(daemon::PoseJournal::Load(state, &entries, &skipped, &error)) << error;
  std::vector<Eigen::Vector3d> directions;
  for (const auto& e : entries) {
    for (const auto& v : e.motion) directions.push_back(model->Correct(doc.theta, v.mag));
  }
  ASSERT_EQ(directions.size(), 1000u);
  const SphereCoverage final_coverage = CoverageOf(directions);
  EXPECT_NEAR(last["filled"].get<int>(), final_coverage.filled,
              std::max(3.0, 0.05 * final_coverage.filled));
  // A hand's 10 s leave most of the sphere empty: the region is named, and holds no value.
  ASSERT_TRUE(last.contains("gap")) << last.dump();
  const nlohmann::json& gap = last["gap"];
  const Eigen::Vector3d centre(gap["direction"][0].get<double>(), gap["direction"][1].get<double>(),
                               gap["direction"][2].get<double>());
  const double radius_deg = gap["radius_deg"].get<double>();
  EXPECT_GT(radius_deg, 25.0);
  EXPECT_GT(gap["empty_area_fraction"].get<double>(), 0.5);
  const std::string text = gap["text"].get<std::string>();
  EXPECT_NE(
      text.find("turn it so that " + gap["name"].get<std::string>() + " points along the field"),
      std::string::npos)
      << text;
  double nearest_deg = 180.0;
  for (const auto& d : directions) {
    nearest_deg = std::min(
        nearest_deg, std::acos(std::clamp(d.normalized().dot(centre), -1.0, 1.0)) * 180 / M_PI);
  }
  EXPECT_GT(nearest_deg, radius_deg - 12.0) << "a bin is 10 x 11.25 degrees";
  fs::remove_all(state);
  fs::remove(path);
}

TEST(FreeMotionStation, AnXbusConsumerStreamAndTheMotionSwitchedOff) {
  const sim::SimCapture capture = Hand(drivers::Protocol::kXbus, 100, 50, "consumer", 5);
  const std::string path = WriteSimCaptureFile(capture, "free_motion_station_xbus");
  daemon::StationOptions options = MotionOptions("", "consumer");
  const Replayed r = Replay(path, options);
  const nlohmann::json& d = r.outcome.result["devices"]["imu"];
  const nlohmann::json& m = d["models"]["magellipsoid"];
  ASSERT_TRUE(m["ok"].get<bool>()) << m.dump();
  EXPECT_EQ(m["model"], "magellipsoid") << m["note"];
  EXPECT_NEAR(d["free"]["motion"]["rate_hz"].get<double>(), 50.0, 0.1);
  SensorClass sensor;
  SensorClassByName("consumer", &sensor);
  ExpectNearTruth(capture, m, daemon::FreeContextFor(options, sensor));

  // [free] motion = false: the still intervals only, and there are none.
  options.free.motion = false;
  const Replayed off = Replay(path, options);
  const nlohmann::json& d2 = off.outcome.result["devices"]["imu"];
  EXPECT_FALSE(d2["free"]["motion"]["enabled"].get<bool>());
  EXPECT_EQ(d2["free"]["motion"]["values"].get<int>(), 0);
  EXPECT_EQ(off.activations, 0);
  fs::remove(path);
}

}  // namespace
}  // namespace turncal
