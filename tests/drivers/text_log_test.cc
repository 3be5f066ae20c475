// Foreign recordings (drivers/capture/text_log.h, issue 22): text logs with a time column and
// triad columns, and imu_tk's pair of `.mat` text files from ../shared/fixtures (skipped with a
// message when that folder is absent).

#include "drivers/capture/text_log.h"

#include <gtest/gtest.h>

#include <cmath>
#include <sstream>

#include "tests/drivers/decoder_test_util.h"

namespace turncal::drivers {
namespace {

TEST(TextLog, ACsvWithAHeaderIsReadScaledAndItsOddLinesCounted) {
  std::istringstream in(
      "time_ms,ax,ay,az,gx,gy,gz\n"
      "# a comment\n"
      "1000,1,2,3,0.1,0.2,0.3\n"
      "1010;1.5;2.5;3.5;0.1;0.2;0.3\n"  // semicolons
      "1020 2 3 4 0.1 0.2 0.3\n"        // blanks
      "1025,2,x,4,0.1,0.2,0.3\n"        // not a number
      "1015,2,3,4,0.1,0.2,0.3\n"        // the time does not increase: dropped
      "\n"
      "1040,2,3\n");  // truncated
  TextLogLayout layout;
  std::string error;
  ASSERT_TRUE(ParseColumnSpec("t,ax,ay,az,gx,gy,gz", &layout, &error)) << error;
  layout.time_scale = 1e-3;
  layout.acc.scale = 9.80665;  // g to m/s^2
  layout.gyr.offset = 0.1;
  std::vector<Sample> samples;
  TextLogStats stats;
  ASSERT_TRUE(ReadTextLog(in, layout, "imu", &samples, &stats, &error)) << error;
  ASSERT_EQ(samples.size(), 3u);
  EXPECT_EQ(stats.samples, 3);
  EXPECT_EQ(stats.lines, 9);
  EXPECT_EQ(stats.skipped, 4);  // the header, the comment, the bad number, the truncated line
  EXPECT_EQ(stats.backwards, 1);
  EXPECT_EQ(stats.first_skipped, "line 1: the time is not a number");
  EXPECT_NEAR(stats.rate_hz(), 100.0, 1e-9);
  EXPECT_EQ(samples[0].device, "imu");
  EXPECT_NEAR(*samples[1].t_device_s, 1.010, 1e-12);
  EXPECT_EQ(samples[1].t_host_ns, 10'000'000);
  EXPECT_EQ(*samples[2].counter, 2u);
  EXPECT_NEAR((*samples[1].acc_mps2)[0], 1.5 * 9.80665, 1e-12);
  EXPECT_NEAR((*samples[2].gyr_radps)[2], 0.2, 1e-12);  // (0.3 - 0.1) x 1
  EXPECT_FALSE(samples[0].mag);
}

TEST(TextLog, BadLayoutsAndLogsWithoutSamplesAreRefusedWithAReason) {
  TextLogLayout layout;
  std::string error;
  EXPECT_FALSE(ParseColumnSpec("t,ax,ay", &layout, &error));
  EXPECT_NE(error.find("three columns"), std::string::npos) << error;
  EXPECT_FALSE(ParseColumnSpec("t,ax,ay,az,ax", &layout, &error));
  EXPECT_NE(error.find("named twice"), std::string::npos) << error;
  EXPECT_FALSE(ParseColumnSpec("t,ax,ay,az,qq", &layout, &error));
  EXPECT_NE(error.find("unknown name 'qq'"), std::string::npos) << error;
  EXPECT_FALSE(ParseColumnSpec("ax,ay,az", &layout, &error));
  EXPECT_NE(error.find("time column"), std::string::npos) << error;
  ASSERT_TRUE(ParseColumnSpec("-,t,mx,my,mz", &layout, &error)) << error;
  EXPECT_EQ(layout.time_column, 1);
  EXPECT_EQ(layout.mag.column[2], 4);
  layout.mag.scale = 0;
  EXPECT_FALSE(layout.IsValid(&error));
  layout.mag.scale = 1;
  std::istringstream in("a,b,c\n,,,\n");
  std::vector<Sample> samples;
  EXPECT_FALSE(ReadTextLog(in, layout, "imu", &samples, nullptr, &error));
  EXPECT_NE(error.find("no line of 2 is a sample"), std::string::npos) << error;
  EXPECT_FALSE(ReadTextLogFile("/nonexistent/log.csv", layout, "imu", &samples, nullptr, &error));
  EXPECT_NE(error.find("cannot open"), std::string::npos) << error;
}

// The real Xsens recording imu_tk ships (../shared/fixtures/README.md): 51 175 rows at ~100 Hz of
// raw counts, the two files at the same times; imu_tk's example starts from the accelerometer
// bias at 32768 counts and the gyro scale 1/6258.
TEST(TextLog, TheImuTkRecordingReadsAsOneStreamOfRawCounts) {
  const auto acc = testing::Fixture("imu_tk/xsens_acc.mat");
  const auto gyr = testing::Fixture("imu_tk/xsens_gyro.mat");
  if (acc.empty() || gyr.empty()) {
    GTEST_SKIP() << "../shared/fixtures is absent: skipping the imu_tk recording";
  }
  TriadColumns a, g;
  a.offset = 32768;
  g.offset = 32768;
  g.scale = 1.0 / 6258;
  std::vector<Sample> samples;
  TextLogStats stats;
  std::string error;
  ASSERT_TRUE(ReadImuTkPair(acc.string(), gyr.string(), a, g, "xsens", &samples, &stats, &error))
      << error;
  ASSERT_EQ(samples.size(), 51175u);
  EXPECT_EQ(stats.skipped, 0);
  EXPECT_EQ(stats.backwards, 0);
  EXPECT_NEAR(stats.rate_hz(), 100.0, 0.1);
  EXPECT_NEAR(*samples[0].t_device_s, 0.02984, 1e-9);
  EXPECT_NEAR(*samples.back().t_device_s, 511.718, 1e-9);
  // The first row of each file: 33108 33329 36429 and 32786 32429 32499 counts.
  EXPECT_NEAR((*samples[0].acc_mps2)[0], 33108 - 32768, 1e-9);
  EXPECT_NEAR((*samples[0].acc_mps2)[2], 36429 - 32768, 1e-9);
  EXPECT_NEAR((*samples[0].gyr_radps)[1], (32429 - 32768) / 6258.0, 1e-12);
  // At rest the gyro reads near its bias, well inside a count range of +-32768.
  for (std::size_t i = 0; i < 100; ++i) EXPECT_LT(samples[i].gyr_radps->norm(), 0.2);
}

}  // namespace
}  // namespace turncal::drivers
