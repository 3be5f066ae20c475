// A rest's noise measured by the station (Station::RestNoiseRequest, {"cmd":"noise"}): started,
// asked, stopped and saved; errors named. The live path on a pty is e2e_live_noise.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "daemon/station/station.h"

namespace turncal {
namespace {

TEST(StationRestNoise, StartStatusStopAndTheSavedFile) {
  const auto dir = std::filesystem::temp_directory_path() / "turncal_station_noise_test";
  std::filesystem::remove_all(dir);
  daemon::StationOptions options;
  options.models = {"accel13"};
  options.state_dir = dir.string();
  daemon::Station station({"imu"}, options, {});

  const nlohmann::json unknown = station.RestNoiseRequest("nosuch", "start");
  EXPECT_EQ(unknown["class"], "ERROR");
  EXPECT_NE(unknown["message"].get<std::string>().find("no device 'nosuch' (devices: imu)"),
            std::string::npos);
  const nlohmann::json idle = station.RestNoiseRequest("imu", "stop");
  EXPECT_EQ(idle["class"], "ERROR");
  EXPECT_NE(idle["message"].get<std::string>().find("nothing is measured on imu"),
            std::string::npos);

  // White gyro noise of density N at 100 Hz (per-sample sigma N sqrt(50)), an accelerometer at
  // rest; no magnetometer.
  const double rate = 100, density = 2e-4;
  std::mt19937_64 rng(39);
  std::normal_distribution<double> normal;
  auto feed = [&](int from, int count) {
    for (int i = from; i < from + count; ++i) {
      Sample s;
      s.t_device_s = i / rate;
      s.t_host_ns = static_cast<std::int64_t>(1e9 * i / rate);
      s.gyr_radps =
          density * std::sqrt(rate / 2) * Eigen::Vector3d(normal(rng), normal(rng), normal(rng));
      s.acc_mps2 = Eigen::Vector3d(0, 0, -9.81) +
                   1e-3 * Eigen::Vector3d(normal(rng), normal(rng), normal(rng));
      station.OnSample(0, s);
    }
  };
  feed(0, 500);  // before the start: not counted
  EXPECT_EQ(station.RestNoiseRequest("imu", "start")["restarted"], false);
  feed(500, 1000);
  EXPECT_EQ(station.RestNoiseRequest("imu", "start")["restarted"], true);  // begins again
  feed(1500, 40000);
  const nlohmann::json status = station.RestNoiseRequest("imu", "status");
  EXPECT_EQ(status["class"], "NOISE");
  EXPECT_EQ(status["state"], "measuring");
  EXPECT_EQ(status["samples"], 40000);
  const nlohmann::json done = station.RestNoiseRequest("imu", "stop");
  EXPECT_EQ(done["state"], "stopped");
  EXPECT_NEAR(done["seconds"].get<double>(), 39999 / rate, 1e-6);
  EXPECT_EQ(done["poses_announced"], 0);
  ASSERT_EQ(done["axes"].size(), 6u);  // acc and gyr; no magnetometer
  for (const auto& a : done["axes"]) {
    if (a["triad"] != "gyr") continue;
    // 40 000 samples: the white density to a couple of percent.
    EXPECT_NEAR(a["white_density"].get<double>(), density, 0.06 * density) << a["axis"];
    EXPECT_FALSE(a["allan"].empty());
  }
  ASSERT_TRUE(done.contains("file")) << done.value("save_error", "");
  const std::string file = done["file"];
  EXPECT_EQ(std::filesystem::path(file).parent_path(), dir / "rest_noise");
  std::ifstream in(file);
  const nlohmann::json saved = nlohmann::json::parse(in, nullptr, false);
  EXPECT_EQ(saved["samples"], 40000);
  // Ended: nothing is measured any more.
  EXPECT_EQ(station.RestNoiseRequest("imu", "status")["class"], "ERROR");
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace turncal
