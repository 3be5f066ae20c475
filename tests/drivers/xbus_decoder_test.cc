#include "drivers/xbus/xbus_decoder.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <bitset>
#include <cmath>
#include <random>
#include <sstream>

#include "tests/drivers/decoder_test_util.h"

namespace turncal::drivers {
namespace {

using testing::CollectingSink;
using testing::Hex;

TEST(Xbus, MtData2ExampleOfProtocolsMd) {
  CollectingSink sink;
  XbusDecoder d("mti", &sink);
  const auto bytes = Hex(
      "FA FF 36 31 10 20 02 DF C5 10 60 04 00 45 9D A0 40 20 0C BE DC 9A FA 3F 54 9F 37 41 1C BB "
      "70 80 20 0C BB AA 5C 80 3B 8C 55 01 BB 81 33 00 E0 20 04 00 00 00 81 45");
  d.Push(bytes, 42);
  ASSERT_EQ(sink.samples.size(), 1u);
  const Sample& s = sink.samples[0];
  EXPECT_EQ(s.counter, 57285u);
  EXPECT_NEAR(*s.t_device_s, 456.2336, 1e-9);
  EXPECT_NEAR(s.acc_mps2->x(), -0.43087, 1e-5);
  EXPECT_NEAR(s.acc_mps2->y(), 0.83055, 1e-5);
  EXPECT_NEAR(s.acc_mps2->z(), 9.79576, 1e-5);
  EXPECT_NEAR(s.gyr_radps->x(), -0.005199, 1e-6);
  EXPECT_NEAR(s.gyr_radps->y(), 0.004283, 1e-6);
  EXPECT_NEAR(s.gyr_radps->z(), -0.003943, 1e-6);
  EXPECT_EQ(s.flags, 0u);  // StatusWord 0x81: no clip bits
  EXPECT_EQ(s.frame, VectorFrame::kEnu);
  EXPECT_EQ(s.t_host_ns, 42);
  EXPECT_EQ(s.device, "mti");
}

TEST(Xbus, CommandVectorsAreFrames) {
  CollectingSink sink;
  XbusDecoder d("mti", &sink);
  for (const char* v : {"FA FF 30 00 D1", "FA FF 31 00 D0", "FA FF 10 00 F1", "FA FF 00 00 01",
                        "FA FF 3F 00 C2", "FA FF 40 00 C1"}) {
    d.Push(Hex(v), 0);
  }
  EXPECT_EQ(d.counters().frames, 6u);
  EXPECT_EQ(sink.frames.kind, (std::vector<std::uint8_t>{0x30, 0x31, 0x10, 0x00, 0x3F, 0x40}));
  d.Push(Hex("FA FF 30 00 D2"), 0);
  EXPECT_EQ(d.counters().bad_checksums, 1u);
}

TEST(Xbus, NumberFormats) {
  // fp12.20: 1.5 = 0x00180000; fp16.32: -2.25 = integer -3 (0xFFFD), fraction 0.75 (0xC0000000).
  const std::uint8_t fp1220[4] = {0x00, 0x18, 0x00, 0x00};
  EXPECT_EQ(xbus::DecodeValue(fp1220, 1), 1.5);
  const std::uint8_t fp1632[6] = {0xC0, 0x00, 0x00, 0x00, 0xFF, 0xFD};
  EXPECT_EQ(xbus::DecodeValue(fp1632, 2), -2.25);
  const std::uint8_t f64[8] = {0x3F, 0xF8, 0, 0, 0, 0, 0, 0};
  EXPECT_EQ(xbus::DecodeValue(f64, 3), 1.5);
}

TEST(Xbus, ItemsThatDoNotFillThePayloadAreRejected) {
  // PacketCounter item claiming 3 bytes with 2 present; checksum made valid.
  std::vector<std::uint8_t> m = {0xFA, 0xFF, 0x36, 0x04, 0x10, 0x20, 0x03, 0x00};
  std::uint8_t sum = 0;
  for (std::size_t i = 1; i < m.size(); ++i) sum = static_cast<std::uint8_t>(sum + m[i]);
  m.push_back(static_cast<std::uint8_t>(-sum));
  CollectingSink sink;
  XbusDecoder d("mti", &sink);
  d.Push(m, 0);
  EXPECT_EQ(d.counters().frames, 0u);
  EXPECT_EQ(d.counters().bad_structure, 1u);
}

// A maximal message that contains the header of another maximal message near its end: the
// decoder looks ahead into the second one, so almost two frames are pending. Fed in chunks of
// several sizes this must neither overflow the buffer (it did, found by review) nor lose count of
// a byte.
TEST(Xbus, LookAheadIntoASecondMaximalMessageStaysInsideTheBuffer) {
  std::vector<std::uint8_t> a(16191, 0);
  auto header = [&](std::size_t at) {
    const std::uint8_t h[6] = {0xFA, 0xFF, 0x36, 0xFF, 0x1F, 0xF9};  // 8185 data bytes
    std::copy(h, h + 6, a.begin() + static_cast<long>(at));
  };
  header(0);
  header(8000);
  unsigned sum = 0;
  for (std::size_t i = 1; i < 8191; ++i) sum += a[i];
  a[8191] = static_cast<std::uint8_t>(-sum);
  for (std::size_t chunk :
       {std::size_t{1000}, std::size_t{4096}, std::size_t{16191}, std::size_t{7}}) {
    CollectingSink sink;
    XbusDecoder d("mti", &sink);
    for (std::size_t at = 0; at < a.size(); at += chunk) {
      d.Push(std::span<const std::uint8_t>(a.data() + at, std::min(chunk, a.size() - at)), 0);
      EXPECT_TRUE(testing::BytesAccountedFor(d)) << chunk;
    }
    const std::vector<std::uint8_t> more(3000, 0);
    d.Push(more, 1);
    d.Finish();
    EXPECT_TRUE(testing::BytesAccountedFor(d)) << chunk;
    EXPECT_EQ(d.pending_bytes(), 0u);
  }
}

TEST(Xbus, LegacyLayoutSizes) {
  XbusLegacyLayout l;
  l.output_mode = 0x0003;
  l.output_settings = 0x00000001;
  EXPECT_EQ(l.PayloadSize(nullptr), 42u);      // PROTOCOLS.md's example
  l.output_settings = 0x00000001 | (2u << 8);  // fp16.32
  EXPECT_EQ(l.PayloadSize(nullptr), 6u + 54u + 2u);
  l.output_mode = 0x4002;
  std::string error;
  EXPECT_FALSE(l.PayloadSize(&error));
  EXPECT_NE(error.find("0x4002"), std::string::npos);
}

// --- The einride captures against their golden files -------------------------------------------

struct GoldenItem {
  std::string header;  // e.g. "Acceleration(Float32)"
  std::vector<std::string> lines;
};
using GoldenMessage = std::vector<GoldenItem>;

std::vector<GoldenMessage> ParseGolden(const std::string& text) {
  std::vector<GoldenMessage> out(1);
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty()) {
      if (!out.back().empty()) out.emplace_back();
    } else if (line.rfind("  ", 0) == 0) {
      out.back().back().lines.push_back(line.substr(2));
    } else {
      out.back().push_back({line.substr(0, line.size() - 1), {}});
    }
  }
  if (out.back().empty()) out.pop_back();
  return out;
}

std::string TrimZeros(std::string s) {
  while (!s.empty() && s.back() == '0') s.pop_back();
  if (!s.empty() && s.back() == '.') s.pop_back();
  return s;
}

// Compares one decoded item with its golden text.
void CompareItem(const xbus::Item& item, const GoldenItem& golden, const std::string& where) {
  const std::string name = golden.header.substr(0, golden.header.find('('));
  ASSERT_EQ(xbus::ItemName(item.type()), name) << where;
  std::vector<xbus::NamedValue> values;
  ASSERT_TRUE(xbus::ItemValues(item, &values)) << where << " " << name;
  const bool fixed = golden.header.find("FP1632") != std::string::npos;
  if (name == "UTCTime") {
    auto v = [&](const char* n) {
      for (const auto& x : values)
        if (std::string(x.name) == n) return static_cast<long>(x.value);
      return -1L;
    };
    const std::string fraction = TrimZeros(fmt::format("{:09d}", v("Ns")));
    const std::string text =
        fmt::format("{:04d}-{:02d}-{:02d}T{:02d}:{:02d}:{:02d}{}Z", v("Year"), v("Month"), v("Day"),
                    v("Hour"), v("Minute"), v("Second"), fraction.empty() ? "" : "." + fraction);
    EXPECT_EQ(text, golden.lines.at(0)) << where;
    return;
  }
  if (name == "StatusWord" || name == "StatusByte") {
    ASSERT_EQ(values.size(), 1u);
    EXPECT_EQ(static_cast<unsigned long>(values[0].value),
              std::stoul(golden.lines.at(0), nullptr, 2))
        << where;
    return;
  }
  ASSERT_EQ(values.size(), golden.lines.size()) << where << " " << name;
  for (std::size_t i = 0; i < values.size(); ++i) {
    const std::string& g = golden.lines[i];
    const auto colon = g.find(':');
    const std::string label = colon == std::string::npos ? "" : g.substr(0, colon);
    const double expected = std::stod(colon == std::string::npos ? g : g.substr(colon + 1));
    EXPECT_EQ(label, values[i].name) << where << " " << name;
    if (fixed || name == "GNSSPVTData" || name == "PacketCounter" || name == "SampleTimeFine") {
      EXPECT_EQ(values[i].value, expected) << where << " " << name << " " << label;
    } else {
      EXPECT_NEAR(values[i].value, expected, 1e-6 * std::abs(expected)) << where << " " << name;
    }
  }
}

void CheckEinride(const std::string& folder) {
  const auto bin = testing::Fixture("xsens/" + folder + "/output.bin");
  const auto golden_path = testing::Fixture("xsens/" + folder + "/output.golden");
  if (bin.empty() || golden_path.empty()) {
    GTEST_SKIP() << "../shared/fixtures is absent: skipping the Xsens capture test";
  }
  const auto data = testing::ReadFile(bin);
  const auto golden = ParseGolden(testing::ReadText(golden_path));
  CollectingSink sink;
  XbusDecoder d("mti", &sink);
  std::mt19937_64 rng(7);
  std::uniform_int_distribution<std::size_t> size(1, 300);
  for (std::size_t at = 0; at < data.size();) {
    const std::size_t n = std::min(data.size() - at, size(rng));
    d.Push(std::span<const std::uint8_t>(data.data() + at, n), 0);
    at += n;
  }
  d.Finish();
  EXPECT_EQ(d.counters().bad_checksums, 0u);
  EXPECT_EQ(d.counters().bytes_skipped, 0u);
  EXPECT_EQ(d.counters().unknown_fields, 0u);
  EXPECT_EQ(d.counters().lost_samples, 0u);
  ASSERT_EQ(sink.frames.bytes.size(), golden.size());
  for (std::size_t m = 0; m < golden.size(); ++m) {
    const auto payload = XbusDecoder::Payload(sink.frames.bytes[m]);
    std::vector<xbus::Item> items;
    ASSERT_TRUE(xbus::ForEachItem(payload, [&](const xbus::Item& i) { items.push_back(i); }));
    ASSERT_EQ(items.size(), golden[m].size()) << "message " << m;
    for (std::size_t i = 0; i < items.size(); ++i) {
      CompareItem(items[i], golden[m][i], fmt::format("{} message {} item {}", folder, m, i));
    }
  }
  // Messages with inertial data became samples; the GNSS-only ones did not.
  EXPECT_EQ(sink.samples.size(), 96u);
}

TEST(Xbus, Einride1Float32MatchesGolden) { CheckEinride("einride-1"); }
TEST(Xbus, Einride3FixedPointMatchesGolden) { CheckEinride("einride-3"); }

}  // namespace
}  // namespace turncal::drivers
