#include "drivers/checksum.h"

#include <gtest/gtest.h>

#include <vector>

namespace turncal::drivers {
namespace {

using Bytes = std::vector<std::uint8_t>;

// Test vectors from PROTOCOLS.md: the packet without its last two bytes, then the checksum.
void ExpectMip(const Bytes& packet) {
  const Bytes body(packet.begin(), packet.end() - 2);
  const std::uint16_t want =
      static_cast<std::uint16_t>(packet[packet.size() - 2] << 8 | packet.back());
  EXPECT_EQ(MipChecksum(body), want);
}

TEST(Checksum, MipMatchesProtocolTestVectors) {
  ExpectMip({0x75, 0x65, 0x01, 0x00, 0xDB, 0x05});
  ExpectMip({0x75, 0x65, 0x01, 0x02, 0x02, 0x01, 0xE0, 0xC6});
  ExpectMip({0x75, 0x65, 0x01, 0x04, 0x04, 0xF1, 0x01, 0x00, 0xD5, 0x6A});
  ExpectMip({0x75, 0x65, 0x01, 0x02, 0x02, 0x02, 0xE1, 0xC7});
  ExpectMip({0x75, 0x65, 0x01, 0x02, 0x02, 0x06, 0xE5, 0xCB});
  ExpectMip({0x75, 0x65, 0x0C, 0x0D, 0x0D, 0x08, 0x01, 0x03, 0x04, 0x00, 0x0A, 0x05, 0x00, 0x0A,
             0x06, 0x00, 0x0A, 0x39, 0x7D});
}

TEST(Checksum, MipSumsWrapModulo256NotFletcher255) {
  const Bytes ff(300, 0xFF);
  const std::uint16_t ck = MipChecksum(ff);
  std::uint8_t a = 0, b = 0;
  for (int i = 0; i < 300; ++i) {
    a = static_cast<std::uint8_t>(a + 0xFF);
    b = static_cast<std::uint8_t>(b + a);
  }
  EXPECT_EQ(ck, a << 8 | b);
}

TEST(Checksum, XbusMakesTheSumAfterThePreambleZero) {
  // GoToConfig: FA FF 30 00 D1.
  EXPECT_EQ(XbusChecksum(Bytes{0xFF, 0x30, 0x00}), 0xD1);
  const Bytes body{0xFF, 0x36, 0x03, 0x10, 0x20, 0x30};
  std::uint8_t sum = XbusChecksum(body);
  for (auto b : body) sum = static_cast<std::uint8_t>(sum + b);
  EXPECT_EQ(sum, 0);
}

TEST(Checksum, Gx2IsTheSumOfAllBytesModulo65536) {
  EXPECT_EQ(Gx2Checksum(Bytes{0xC2, 0x01, 0x02}), 0xC5);
  EXPECT_EQ(Gx2Checksum(Bytes(300, 0xFF)), static_cast<std::uint16_t>(300 * 0xFF));
}

}  // namespace
}  // namespace turncal::drivers

namespace turncal::drivers {
namespace {

// The vectorised checksums equal the byte-at-a-time definitions for every length 0..600.
TEST(Checksum, FastFormsEqualTheDefinitions) {
  std::vector<std::uint8_t> data(600);
  std::uint32_t x = 12345;
  for (auto& b : data) {
    x = x * 1103515245u + 12345u;
    b = static_cast<std::uint8_t>(x >> 16);
  }
  for (std::size_t n = 0; n <= data.size(); ++n) {
    const std::span<const std::uint8_t> span(data.data(), n);
    ASSERT_EQ(MipChecksumFast(data.data(), n), MipChecksum(span)) << n;
    std::uint8_t sum = 0;
    for (auto b : span) sum = static_cast<std::uint8_t>(sum + b);
    ASSERT_EQ(ByteSum(data.data(), n) & 0xFF, sum) << n;
    ASSERT_EQ(ByteSum(data.data(), n) & 0xFFFF, Gx2Checksum(span)) << n;
  }
}

}  // namespace
}  // namespace turncal::drivers
