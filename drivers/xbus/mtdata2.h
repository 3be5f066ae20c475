#pragma once
// Xsens MTData2 items (PROTOCOLS.md "MTData2"): XDI u16 | size u8 | data, in any order.

#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

#include "core/sequencing/sample.h"
#include "drivers/bytes.h"

namespace turncal::drivers::xbus {

struct Item {
  std::uint16_t xdi = 0;
  std::span<const std::uint8_t> data;

  std::uint16_t type() const { return static_cast<std::uint16_t>(xdi & 0xFFF0); }
  int format() const { return xdi & 0x3; }  // 0 f32, 1 fp12.20, 2 fp16.32, 3 f64
};

// Known item types.
enum : std::uint16_t {
  kTemperature = 0x0810,
  kUtcTime = 0x1010,
  kPacketCounter = 0x1020,
  kSampleTimeFine = 0x1060,
  kSampleTimeCoarse = 0x1070,
  kQuaternion = 0x2010,
  kRotationMatrix = 0x2020,
  kEulerAngles = 0x2030,
  kDeltaV = 0x4010,
  kAcceleration = 0x4020,
  kFreeAcceleration = 0x4030,
  kAltitudeEllipsoid = 0x5020,
  kLatLon = 0x5040,
  kGnssPvtData = 0x7010,
  kRateOfTurn = 0x8020,
  kDeltaQ = 0x8030,
  kMagneticField = 0xC020,
  kVelocityXyz = 0xD010,
  kStatusByte = 0xE010,
  kStatusWord = 0xE020,
};

// Bytes per value of a number format: 4, 4, 6, 8.
inline int ValueSize(int format) {
  constexpr int kSizes[4] = {4, 4, 6, 8};
  return kSizes[format & 3];
}
// One value at p in the given format (fp12.20: int32 / 2^20; fp16.32: (int16 hi * 2^32 + u32
// lo) / 2^32 with the fraction first on the wire).
inline double DecodeValue(const std::uint8_t* p, int format) {
  switch (format & 3) {
    case 0:
      return LoadF32(p);
    case 1:
      return static_cast<std::int32_t>(LoadU32(p)) / 1048576.0;
    case 2: {
      const auto fraction = LoadU32(p);
      const auto integer = static_cast<std::int16_t>(LoadU16(p + 4));
      return (static_cast<double>(integer) * 4294967296.0 + fraction) / 4294967296.0;
    }
    default:
      return LoadF64(p);
  }
}
// The item's values as numbers (size / ValueSize); returns how many were written (at most max),
// or -1 when the size is not a whole number of values.
inline int DecodeValues(const Item& item, double* out, int max) {
  const int size = ValueSize(item.format());
  if (item.data.size() % static_cast<std::size_t>(size) != 0) return -1;
  const int n = std::min(max, static_cast<int>(item.data.size()) / size);
  for (int i = 0; i < n; ++i) out[i] = DecodeValue(item.data.data() + i * size, item.format());
  return n;
}
// The frame bits (XDI & 0xC) of a vector item.
VectorFrame FrameOf(std::uint16_t xdi);
// "Acceleration", "RateOfTurn", ... ; nullptr when unknown.
const char* ItemName(std::uint16_t type);

// Calls f(item) for every item of an MTData2 payload; false (after calling f for the items before
// the fault) when the items do not fill the payload exactly.
template <class F>
bool ForEachItem(std::span<const std::uint8_t> payload, F&& f) {
  std::size_t at = 0;
  while (at < payload.size()) {
    if (payload.size() - at < 3) return false;
    const std::size_t size = payload[at + 2];
    if (payload.size() - at - 3 < size) return false;
    f(Item{static_cast<std::uint16_t>(payload[at] << 8 | payload[at + 1]),
           payload.subspan(at + 3, size)});
    at += 3 + size;
  }
  return true;
}

// A decoded value with the label Xsens' documentation gives it ("X", "Q0", "Lat", "ITOW", ...;
// empty for single-value items). Integers are exact in a double.
struct NamedValue {
  const char* name = "";
  double value = 0.0;
};

// Every value of a known item, for diagnostics (`turncal decode`) and golden-file tests: vectors
// X/Y/Z, quaternions Q0-Q3, LatLon Lat/Lon, UTCTime Ns/Year/Month/Day/Hour/Minute/Second/Flags,
// GNSSPVTData's 35 fields, counters, times and status words as integers. False when the item is
// unknown or its size does not match its type.
bool ItemValues(const Item& item, std::vector<NamedValue>* out);

// True when the payload's items fill it exactly (structural validation before use).
bool ItemsFillPayload(std::span<const std::uint8_t> payload);

}  // namespace turncal::drivers::xbus
