#include "drivers/capture/tcap.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace turncal::drivers {
namespace {

CaptureHeader Header() {
  CaptureHeader h;
  CaptureDevice legacy{"mtx", Protocol::kXbusLegacy, 115200, 0x0003, 0x00000001};
  h.devices = {{"imu", Protocol::kMip, 921600, std::nullopt, std::nullopt}, legacy};
  h.created = "2026-11-22T04:00:00Z";
  h.note = "test \"quoted\" note";
  return h;
}

std::vector<CaptureRecord> Records() {
  std::vector<CaptureRecord> r;
  r.push_back({RecordType::kReceived, 0, 0, {0x75, 0x65, 0x01, 0x00, 0xDB, 0x05}});
  r.push_back({RecordType::kSent, 1, 1'000'000, {0xFA, 0xFF, 0x30, 0x00, 0xD1}});
  const std::string event = R"({"event":"pose","phi_deg":90,"gamma_deg":0,"psi_deg":45})";
  r.push_back({RecordType::kEvent, 0, 2'000'000, {event.begin(), event.end()}});
  r.push_back({RecordType::kReceived, 1, 0xFFFFFFFFFFull, {}});
  std::vector<std::uint8_t> big(3000);
  for (std::size_t i = 0; i < big.size(); ++i) big[i] = static_cast<std::uint8_t>(i * 7);
  r.push_back({RecordType::kReceived, 0, 5'000'000'000ull, big});
  return r;
}

TEST(Tcap, WriteThenReadPreservesEveryByteAndRecordInOrder) {
  const auto path = std::filesystem::temp_directory_path() / "turncal_tcap_test.tcap";
  std::string error;
  auto w = CaptureWriter::Create(path.string(), Header(), &error);
  ASSERT_NE(w, nullptr) << error;
  for (const auto& r : Records())
    ASSERT_TRUE(w->Append(r.type, r.device, r.t_ns, r.payload, &error));
  ASSERT_TRUE(w->Close(&error)) << error;

  CaptureReader reader;
  ASSERT_TRUE(reader.Open(path.string(), &error)) << error;
  EXPECT_EQ(reader.header().devices.size(), 2u);
  EXPECT_EQ(reader.header().devices[1].protocol, Protocol::kXbusLegacy);
  EXPECT_EQ(reader.header().devices[1].output_mode, 0x0003);
  EXPECT_EQ(reader.header().devices[1].output_settings, 0x00000001u);
  EXPECT_FALSE(reader.header().devices[0].output_mode);
  EXPECT_EQ(reader.header().devices[0].baud, 921600);
  EXPECT_EQ(reader.header().note, Header().note);
  CaptureRecord r;
  std::size_t i = 0;
  const auto expected = Records();
  while (reader.Next(&r)) {
    ASSERT_LT(i, expected.size());
    EXPECT_EQ(r.type, expected[i].type);
    EXPECT_EQ(r.device, expected[i].device);
    EXPECT_EQ(r.t_ns, expected[i].t_ns);
    EXPECT_EQ(r.payload, expected[i].payload);
    ++i;
  }
  EXPECT_EQ(i, expected.size());
  EXPECT_FALSE(reader.truncated());
  EXPECT_TRUE(reader.error().empty());
  std::filesystem::remove(path);
}

// A file is read a MiB at a time: records that straddle the reads (sizes 1 to 70 000 bytes,
// 6 MiB in all, a 3 MiB one among them) come back whole and in order, the position reaches the
// size, and a file cut inside its last record still ends cleanly with the rest counted.
TEST(Tcap, ALargeFileIsReadInPiecesWithEveryRecordWhole) {
  const auto path = std::filesystem::temp_directory_path() / "turncal_tcap_large.tcap";
  std::string error;
  auto w = CaptureWriter::Create(path.string(), Header(), &error);
  ASSERT_NE(w, nullptr) << error;
  std::vector<std::vector<std::uint8_t>> payloads;
  std::size_t total = 0;
  for (std::size_t k = 0; total < (3u << 20); ++k) {
    std::vector<std::uint8_t> p((k * 7919) % 70000 + 1);
    for (std::size_t i = 0; i < p.size(); ++i) p[i] = static_cast<std::uint8_t>(i + k);
    total += p.size();
    payloads.push_back(std::move(p));
  }
  payloads.emplace_back(3u << 20, 0x5A);
  for (std::size_t k = 0; k < payloads.size(); ++k) {
    ASSERT_TRUE(w->Append(RecordType::kReceived, 0, k, payloads[k], &error)) << error;
  }
  ASSERT_TRUE(w->Close(&error)) << error;
  const auto size = std::filesystem::file_size(path);
  for (const std::uintmax_t cut : {std::uintmax_t{0}, std::uintmax_t{1000}}) {
    std::filesystem::resize_file(path, size - cut);
    CaptureReader reader;
    ASSERT_TRUE(reader.Open(path.string(), &error)) << error;
    EXPECT_EQ(reader.size(), size - cut);
    CaptureRecord r;
    std::size_t k = 0;
    while (reader.Next(&r)) {
      ASSERT_LT(k, payloads.size());
      ASSERT_EQ(r.t_ns, k);
      ASSERT_EQ(r.payload, payloads[k]) << "record " << k;
      ++k;
    }
    EXPECT_TRUE(reader.error().empty()) << reader.error();
    if (cut == 0) {
      EXPECT_EQ(k, payloads.size());
      EXPECT_FALSE(reader.truncated());
      EXPECT_EQ(reader.position(), size);
    } else {
      EXPECT_EQ(k, payloads.size() - 1);  // the last record lost its end
      EXPECT_TRUE(reader.truncated());
      EXPECT_EQ(reader.trailing_bytes(), payloads.back().size() + kCaptureRecordHeader - cut);
    }
  }
  std::filesystem::remove(path);
}

TEST(Tcap, ATruncatedCaptureIsReadableUpToItsLastWholeRecordAtEveryOffset) {
  const std::string header = EncodeCaptureHeader(Header());
  std::vector<std::uint8_t> file(header.begin(), header.end());
  std::vector<std::size_t> ends;  // offsets where a record ends
  for (const auto& r : Records()) {
    AppendCaptureRecord(r.type, r.device, r.t_ns, r.payload, &file);
    ends.push_back(file.size());
  }
  for (std::size_t cut = 0; cut <= file.size(); ++cut) {
    CaptureReader reader;
    std::string error;
    const bool parsed = reader.Parse({file.begin(), file.begin() + static_cast<long>(cut)}, &error);
    if (cut < header.size()) {
      EXPECT_FALSE(parsed) << cut;
      continue;
    }
    ASSERT_TRUE(parsed) << cut << ": " << error;
    std::size_t whole = 0;
    for (std::size_t e : ends) whole += e <= cut;
    CaptureRecord r;
    std::size_t n = 0;
    while (reader.Next(&r)) ++n;
    EXPECT_EQ(n, whole) << cut;
    const bool at_boundary =
        cut == header.size() || std::find(ends.begin(), ends.end(), cut) != ends.end();
    EXPECT_EQ(reader.truncated(), !at_boundary) << cut;
    EXPECT_TRUE(reader.error().empty()) << cut;
  }
}

TEST(Tcap, CorruptRecordsAndHeadersAreClearErrors) {
  std::string error;
  CaptureReader reader;
  EXPECT_FALSE(reader.Parse({'x', 'y'}, &error));
  EXPECT_NE(error.find("TCAP1"), std::string::npos);
  const std::string bad_json = "TCAP1 {not json\n";
  EXPECT_FALSE(reader.Parse({bad_json.begin(), bad_json.end()}, &error));
  const std::string header = EncodeCaptureHeader(Header());
  std::vector<std::uint8_t> file(header.begin(), header.end());
  AppendCaptureRecord(RecordType::kReceived, 0, 1, std::vector<std::uint8_t>{1, 2, 3}, &file);
  file.push_back('X');  // not a record type
  for (int i = 0; i < 13; ++i) file.push_back(0);
  ASSERT_TRUE(reader.Parse(file, &error)) << error;
  CaptureRecord r;
  EXPECT_TRUE(reader.Next(&r));
  EXPECT_FALSE(reader.Next(&r));
  EXPECT_NE(reader.error().find("corrupt record"), std::string::npos);
}

TEST(Tcap, AFullDiskIsAClearError) {
  if (!std::filesystem::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  std::string error;
  EXPECT_EQ(CaptureWriter::Create("/dev/full", Header(), &error), nullptr);
  EXPECT_NE(error.find("No space"), std::string::npos) << error;
}

}  // namespace
}  // namespace turncal::drivers
