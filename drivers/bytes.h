#pragma once
// Big-endian loads and stores (every protocol here is big-endian on the wire).

#include <bit>
#include <cstdint>
#include <cstring>
#include <vector>

namespace turncal::drivers {

inline std::uint16_t LoadU16(const std::uint8_t* p) {
  return static_cast<std::uint16_t>(p[0] << 8 | p[1]);
}
inline std::uint32_t LoadU32(const std::uint8_t* p) {
  std::uint32_t v;
  std::memcpy(&v, p, 4);
  return std::endian::native == std::endian::little ? __builtin_bswap32(v) : v;
}
inline std::uint64_t LoadU64(const std::uint8_t* p) {
  std::uint64_t v;
  std::memcpy(&v, p, 8);
  return std::endian::native == std::endian::little ? __builtin_bswap64(v) : v;
}
inline float LoadF32(const std::uint8_t* p) { return std::bit_cast<float>(LoadU32(p)); }
inline double LoadF64(const std::uint8_t* p) { return std::bit_cast<double>(LoadU64(p)); }

inline void PutU8(std::vector<std::uint8_t>* out, std::uint8_t v) { out->push_back(v); }
inline void PutU16(std::vector<std::uint8_t>* out, std::uint16_t v) {
  out->push_back(static_cast<std::uint8_t>(v >> 8));
  out->push_back(static_cast<std::uint8_t>(v));
}
inline void PutU32(std::vector<std::uint8_t>* out, std::uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) out->push_back(static_cast<std::uint8_t>(v >> s));
}
inline void PutU64(std::vector<std::uint8_t>* out, std::uint64_t v) {
  for (int s = 56; s >= 0; s -= 8) out->push_back(static_cast<std::uint8_t>(v >> s));
}
inline void PutF32(std::vector<std::uint8_t>* out, float v) {
  PutU32(out, std::bit_cast<std::uint32_t>(v));
}
inline void PutF64(std::vector<std::uint8_t>* out, double v) {
  PutU64(out, std::bit_cast<std::uint64_t>(v));
}

}  // namespace turncal::drivers
