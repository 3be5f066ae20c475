// Foreign recordings (drivers/capture/text_log.h, issue 22): text logs with a time column and
// triad columns, and imu_tk's pair of `.mat` text files from ../shared/fixtures (skipped with a
// message when that folder is absent).

#include "drivers/capture/text_log.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>

#include <fmt/format.h>

#include "core/analysis/sphere_coverage.h"
#include "core/sequencing/sequencer.h"
#include "tests/drivers/decoder_test_util.h"

namespace turncal::drivers {
namespace {

// The imu_tk recording's two files, or false when ../shared/fixtures is absent.
bool ImuTkFiles(std::string* acc, std::string* gyr) {
  const auto a = testing::Fixture("imu_tk/xsens_acc.mat");
  const auto g = testing::Fixture("imu_tk/xsens_gyro.mat");
  *acc = a.string();
  *gyr = g.string();
  return !a.empty() && !g.empty();
}

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
  std::string acc, gyr;
  if (!ImuTkFiles(&acc, &gyr)) {
    GTEST_SKIP() << "../shared/fixtures is absent: skipping the imu_tk recording";
  }
  TriadColumns a, g;
  a.offset = 32768;
  g.offset = 32768;
  g.scale = 1.0 / 6258;
  std::vector<Sample> samples;
  TextLogStats stats;
  std::string error;
  ASSERT_TRUE(ReadImuTkPair(acc, gyr, a, g, "xsens", &samples, &stats, &error)) << error;
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

// Toward free mode (issue 22): the sequencer, given as many poses as the recording could hold
// and no table, takes every still segment of the imu_tk recording; its thresholds come from the
// noise it measures over the first second of the 50 s rest, not from a hand-set threshold. The
// accelerometer is scaled roughly to m/s^2 (|counts - 32768| is ~3720 at rest), which only the
// drift allowance's units need. Measured: the rest and 39 positions (40 segments), 4 segments
// shorter than the 1 s dwell skipped; many positions repeat, and their gravity directions fill 19
// of MicroStrain's 576 bins (3.3 %).
TEST(TextLog, TheImuTkRecordingsStillSegmentsAreFoundFromTheMeasuredNoise) {
  std::string acc, gyr;
  if (!ImuTkFiles(&acc, &gyr)) {
    GTEST_SKIP() << "../shared/fixtures is absent: skipping the imu_tk recording";
  }
  TriadColumns a, g;
  a.offset = g.offset = 32768;
  a.scale = 9.81744 / 3720;
  g.scale = 1.0 / 6258;
  std::vector<Sample> samples;
  std::string error;
  ASSERT_TRUE(ReadImuTkPair(acc, gyr, a, g, "xsens", &samples, nullptr, &error)) << error;
  SequencerOptions options;
  options.dwell_s = 1.0;
  std::vector<Eigen::Vector3d> down;
  int skipped = 0;
  bool measured = false;
  Sequencer sequencer(options, [&](const SequencerEvent& e) {
    if (e.kind == SequencerEventKind::kNoiseMeasured) measured = true;
    if (e.kind == SequencerEventKind::kSegmentSkipped) ++skipped;
    if (e.kind == SequencerEventKind::kCaptured && e.record) {
      down.push_back(-e.record->acc->mean);
      if (std::getenv("TURNCAL_PRINT_SEGMENTS")) {
        std::printf("segment %2d: %7.2f s to %7.2f s, f = %s\n", e.index, e.record->t_start_s,
                    e.record->t_end_s,
                    fmt::format("[{:.3f}, {:.3f}, {:.3f}]", e.record->acc->mean.x(),
                                e.record->acc->mean.y(), e.record->acc->mean.z())
                        .c_str());
      }
    }
  });
  ASSERT_TRUE(sequencer.SetSchedule(std::vector<TablePose>(80), &error)) << error;
  for (const Sample& s : samples) sequencer.Push(s);
  sequencer.Finish(samples.back().t_host_ns);
  EXPECT_TRUE(measured);
  // imu_tk's documentation speaks of about 37 positions after the rest.
  EXPECT_GE(down.size(), 38u);
  EXPECT_LE(down.size(), 44u);
  EXPECT_LE(skipped, 6);
  const SphereCoverage coverage = CoverageOf(down);
  EXPECT_GE(coverage.filled, 15);
  EXPECT_LT(coverage.fraction(), 0.1);  // a hand tumble of ~40 positions: a few % of the sphere
}

}  // namespace
}  // namespace turncal::drivers
