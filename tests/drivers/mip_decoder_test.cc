#include "drivers/mip/mip_decoder.h"

#include <gtest/gtest.h>

#include <fmt/format.h>

#include <map>
#include <random>

#include "drivers/bytes.h"
#include "drivers/checksum.h"
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

// A sensor-set (0x80) packet: `fields` are (descriptor, payload) pairs.
std::vector<std::uint8_t> SensorPacket(
    const std::vector<std::pair<std::uint8_t, std::vector<std::uint8_t>>>& fields) {
  std::vector<std::uint8_t> out = {0x75, 0x65, 0x80, 0x00};
  for (const auto& [desc, payload] : fields) {
    out.push_back(static_cast<std::uint8_t>(payload.size() + 2));
    out.push_back(desc);
    out.insert(out.end(), payload.begin(), payload.end());
  }
  out[3] = static_cast<std::uint8_t>(out.size() - 4);
  PutU16(&out, MipChecksum(out));
  return out;
}

std::vector<std::uint8_t> Triad(float x, float y, float z) {
  std::vector<std::uint8_t> out;
  PutF32(&out, x);
  PutF32(&out, y);
  PutF32(&out, z);
  return out;
}

std::vector<std::uint8_t> Ticks(std::uint32_t ticks) {  // 0x0E: 16 us ticks
  std::vector<std::uint8_t> out;
  PutU32(&out, ticks);
  return out;
}

std::vector<std::uint8_t> Temperature(float celsius) {  // 0x14: min, max, mean
  std::vector<std::uint8_t> out;
  for (int i = 0; i < 3; ++i) PutF32(&out, celsius);
  return out;
}

// A sample split over two packets with the same timestamp (accel + gyro, then mag): the first is
// emitted when the next packet arrives; once the stream has shown that a sample is accel, gyro
// and mag, every later one is emitted as soon as its mag packet arrives.
TEST(Mip, WholeSampleIsEmittedWithoutWaitingForTheNextPacket) {
  CollectingSink sink;
  MipDecoder d("imu", &sink);
  for (std::uint32_t k = 0; k < 20; ++k) {
    const auto a =
        SensorPacket({{0x04, Triad(0, 0, -1)}, {0x05, Triad(0.1f, 0, 0)}, {0x0E, Ticks(k)}});
    const auto m = SensorPacket({{0x06, Triad(0.2f, 0, 0.4f)}, {0x0E, Ticks(k)}});
    d.Push(a, k * 10);
    EXPECT_EQ(sink.samples.size(), k) << "packet " << k << " (accel, gyro)";
    d.Push(m, k * 10 + 1);
    EXPECT_EQ(sink.samples.size(), k == 0 ? 0u : k + 1) << "packet " << k << " (mag)";
  }
  d.Finish();
  ASSERT_EQ(sink.samples.size(), 20u);
  for (std::size_t k = 0; k < 20; ++k) {
    const Sample& s = sink.samples[k];
    EXPECT_TRUE(s.acc_mps2 && s.gyr_radps && s.mag) << k;
    EXPECT_DOUBLE_EQ(*s.t_device_s, static_cast<double>(k) * 16e-6);
    EXPECT_EQ(s.t_host_ns, static_cast<std::int64_t>(k * 10));  // the first packet's time
  }
}

// A device that starts sending a field in a packet of its own (temperature, after samples that
// had none): the first such sample has gone out without it, its temperature comes as a sample of
// its own, and from then on samples wait for the next packet and come out whole.
TEST(Mip, EarlyEmissionStopsWhenAPacketWouldHaveJoinedAnEmittedSample) {
  CollectingSink sink;
  MipDecoder d("imu", &sink);
  const auto whole = [](std::uint32_t k) {
    return SensorPacket({{0x04, Triad(0, 0, -1)}, {0x06, Triad(0.2f, 0, 0.4f)}, {0x0E, Ticks(k)}});
  };
  for (std::uint32_t k = 0; k < 5; ++k) d.Push(whole(k), k);
  ASSERT_EQ(sink.samples.size(), 5u);  // the first waited for the second; the rest at once
  for (std::uint32_t k = 5; k < 10; ++k) {
    d.Push(whole(k), k);
    d.Push(SensorPacket({{0x14, Temperature(25.0f)}, {0x0E, Ticks(k)}}), k);
  }
  d.Finish();
  // 5 + the split sample of k = 5 in two parts + k = 6..9 whole.
  ASSERT_EQ(sink.samples.size(), 11u);
  EXPECT_FALSE(sink.samples[5].temp_c);
  EXPECT_TRUE(sink.samples[6].temp_c && !sink.samples[6].acc_mps2);
  for (std::size_t i = 7; i < 11; ++i) {
    EXPECT_TRUE(sink.samples[i].acc_mps2 && sink.samples[i].mag && sink.samples[i].temp_c) << i;
  }
}

// The real capture (accel/gyro packets, mag in packets of its own without a timestamp): early
// emission gives exactly the samples of waiting for the next packet, and most of them earlier.
TEST(Mip, FixtureEarlyEmissionGivesTheSameSamples) {
  const auto path = testing::Fixture("microstrain/mip_sdk/mip_data.bin");
  if (path.empty()) GTEST_SKIP() << "../shared/fixtures is absent: skipping the MIP capture test";
  const auto data = testing::ReadFile(path);
  CollectingSink early_sink, lazy_sink;
  MipDecoder early("imu", &early_sink), lazy("imu", &lazy_sink, 34'000'000, false);
  std::size_t ahead = 0;
  for (std::size_t at = 0; at + 4 <= data.size();) {
    ASSERT_EQ(data[at], 0x75);
    const std::size_t n = 6u + data[at + 3];
    const std::span<const std::uint8_t> packet(data.data() + at, n);
    early.Push(packet, static_cast<std::int64_t>(at));
    lazy.Push(packet, static_cast<std::int64_t>(at));
    if (early_sink.samples.size() > lazy_sink.samples.size()) ++ahead;
    at += n;
  }
  early.Finish();
  lazy.Finish();
  ASSERT_EQ(early_sink.samples.size(), lazy_sink.samples.size());
  for (std::size_t i = 0; i < early_sink.samples.size(); ++i) {
    const Sample &a = early_sink.samples[i], &b = lazy_sink.samples[i];
    EXPECT_EQ(a.t_host_ns, b.t_host_ns) << i;
    EXPECT_EQ(a.t_device_s, b.t_device_s) << i;
    EXPECT_EQ(a.acc_mps2.has_value(), b.acc_mps2.has_value()) << i;
    EXPECT_EQ(a.mag.has_value(), b.mag.has_value()) << i;
    if (a.mag && b.mag) {
      EXPECT_EQ(*a.mag, *b.mag) << i;
    }
    EXPECT_EQ(a.temp_c, b.temp_c) << i;
  }
  // Packets after which the early decoder had emitted a sample the other still held.
  EXPECT_GT(ahead, early_sink.samples.size() / 4);
  std::printf("fixture: %zu samples; after %zu packets the early decoder was a sample ahead\n",
              early_sink.samples.size(), ahead);
}

}  // namespace
}  // namespace turncal::drivers
