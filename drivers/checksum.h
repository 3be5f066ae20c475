#pragma once
// Checksums of the three protocol families (PROTOCOLS.md). Pure functions over byte spans.

#include <cstdint>
#include <span>

namespace turncal::drivers {

// MIP: two 8-bit sums wrapping modulo 256 over sync bytes through the last payload byte;
// returns (a << 8) | b, the order they are sent in.
std::uint16_t MipChecksum(std::span<const std::uint8_t> bytes);

// Legacy GX2/GX3-25: sum of all bytes modulo 65536 (sent big-endian).
std::uint16_t Gx2Checksum(std::span<const std::uint8_t> bytes);

// Xbus: the byte that makes the sum of everything after the preamble zero modulo 256. `bytes`
// starts at BID and ends at the last data byte.
std::uint8_t XbusChecksum(std::span<const std::uint8_t> bytes);

}  // namespace turncal::drivers
