#include "drivers/mip/mip_decoder.h"

#include <gtest/gtest.h>

#include <fmt/format.h>

#include <map>
#include <random>

#include "tests/drivers/decoder_test_util.h"

namespace turncal::drivers {
namespace {

using testing::CollectingSink;
using testing::Hex;

TEST(Mip, TestVectorsOfProtocolsMdAreAcceptedFrames) {
  CollectingSink sink;
  MipDecoder d("imu", &sink);
  for (const char* v :
       {"75 65 01 00 DB 05", "75 65 01 02 02 01 E0 C6", "75 65 01 04 04 F1 01 00 D5 6A",
        "75 65 01 02 02 02 E1 C7", "75 65 01 02 02 06 E5 CB", "75 65 01 02 02 03 E2 C8",
        "75 65 0C 0D 0D 08 01 03 04 00 0A 05 00 0A 06 00 0A 39 7D"}) {
    const auto bytes = Hex(v);
    d.Push(bytes, 0);
  }
  EXPECT_EQ(d.counters().frames, 7u);
  EXPECT_EQ(d.counters().bad_checksums, 0u);
  EXPECT_EQ(d.counters().bytes_skipped, 0u);
  EXPECT_EQ(sink.frames.kind[2], 0x01);
  EXPECT_EQ(sink.frames.kind[6], 0x0C);
  EXPECT_TRUE(sink.samples.empty());
  // A flipped checksum byte is a bad checksum, not a frame.
  auto bad = Hex("75 65 01 02 02 01 E0 C7");
  d.Push(bad, 1);
  d.Finish();
  EXPECT_EQ(d.counters().frames, 7u);
  EXPECT_EQ(d.counters().bad_checksums, 1u);
  EXPECT_TRUE(testing::BytesAccountedFor(d));
}

// The reference facts of ../shared/fixtures/README.md for mip_data.bin.
void CheckMipFixture(std::size_t max_chunk, std::uint64_t seed) {
  const auto path = testing::Fixture("microstrain/mip_sdk/mip_data.bin");
  if (path.empty()) GTEST_SKIP() << "../shared/fixtures is absent: skipping the MIP capture test";
  const auto data = testing::ReadFile(path);
  ASSERT_EQ(data.size(), 368940u);
  CollectingSink sink;
  MipDecoder d("imu", &sink);
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<std::size_t> size(1, max_chunk);
  for (std::size_t at = 0; at < data.size();) {
    const std::size_t n = std::min(data.size() - at, max_chunk == 0 ? data.size() : size(rng));
    d.Push(std::span<const std::uint8_t>(data.data() + at, n), static_cast<std::int64_t>(at));
    at += n;
  }
  d.Finish();
  const DecoderCounters& c = d.counters();
  EXPECT_EQ(c.frames, 8384u);
  EXPECT_EQ(c.bad_checksums, 0u);
  EXPECT_EQ(c.bad_structure, 0u);
  EXPECT_EQ(c.bytes_skipped, 0u);  // 0 trailing bytes
  EXPECT_EQ(c.bytes_in_frames, data.size());
  std::map<std::string, int> signature;
  for (const auto& frame : sink.frames.bytes) {
    std::string key = fmt::format("{:02X}", frame[2]);
    for (std::size_t at = 4; at < 4u + frame[3]; at += frame[at])
      key += fmt::format(" {:02X}", frame[at + 1]);
    ++signature[key];
  }
  const std::map<std::string, int> expected = {{"80 D5 D6 04 05", 3579},
                                               {"80 06", 1790},
                                               {"80 D5 D6 04 05 06 0C", 894},
                                               {"80 06 0C", 894},
                                               {"82 D5 05", 714},
                                               {"A0 D5 D6", 512},
                                               {"01 F1", 1}};
  EXPECT_EQ(signature, expected);
  ASSERT_FALSE(sink.samples.empty());
  const Sample& first = sink.samples.front();
  ASSERT_TRUE(first.acc_mps2 && first.gyr_radps);
  const Eigen::Vector3d acc_g = *first.acc_mps2 / kStandardGravity_mps2;
  EXPECT_NEAR(acc_g.x(), 0.01741764, 1e-8);
  EXPECT_NEAR(acc_g.y(), -0.00666524, 1e-8);
  EXPECT_NEAR(acc_g.z(), -0.98564005, 1e-8);
  EXPECT_NEAR(first.gyr_radps->x(), -0.00303059, 1e-8);
  EXPECT_NEAR(first.gyr_radps->y(), 0.00031147, 1e-8);
  EXPECT_NEAR(first.gyr_radps->z(), -0.00426879, 1e-8);
  // The first mag arrives in its own packet without a timestamp and joins the first sample.
  ASSERT_TRUE(first.mag);
  EXPECT_NEAR(first.mag->x(), 0.06127914, 1e-8);
  EXPECT_NEAR(first.mag->y(), 0.28442311, 1e-8);
  EXPECT_NEAR(first.mag->z(), 0.24413999, 1e-8);
  ASSERT_TRUE(first.t_device_s);
  EXPECT_EQ(c.samples, sink.samples.size());
  EXPECT_TRUE(testing::BytesAccountedFor(d));
}

TEST(Mip, FixtureFedWhole) { CheckMipFixture(0, 1); }
TEST(Mip, FixtureFedInRandomChunks) { CheckMipFixture(700, 2); }
TEST(Mip, FixtureFedByteByByte) { CheckMipFixture(1, 3); }

}  // namespace
}  // namespace turncal::drivers
