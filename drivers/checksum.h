#pragma once
// Checksums of the three protocol families (PROTOCOLS.md). Pure functions over byte spans.

#include <cstddef>
#include <cstdint>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#include <span>

namespace turncal::drivers {

// MIP: two 8-bit sums wrapping modulo 256 over sync bytes through the last payload byte;
// returns (a << 8) | b, the order they are sent in.
std::uint16_t MipChecksum(std::span<const std::uint8_t> bytes);

// The same two sums, computed as a = sum x_i and b = n a - sum i x_i (mod 256) over n bytes,
// 16 bytes at a time with SSE2 where available; for the scanners' hot path.
inline std::uint16_t MipChecksumFast(const std::uint8_t* p, std::size_t n) {
  std::uint32_t s0 = 0, t = 0;
  std::size_t i = 0;
#if defined(__SSE2__)
  const __m128i zero = _mm_setzero_si128();
  const __m128i w_lo = _mm_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7);
  const __m128i w_hi = _mm_setr_epi16(8, 9, 10, 11, 12, 13, 14, 15);
  __m128i weighted = zero;
  for (; i + 16 <= n; i += 16) {
    const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(p + i));
    const __m128i sad = _mm_sad_epu8(v, zero);
    const auto block =
        static_cast<std::uint32_t>(_mm_cvtsi128_si32(sad) + _mm_extract_epi16(sad, 4));
    t += static_cast<std::uint32_t>(i) * block;
    s0 += block;
    weighted =
        _mm_add_epi32(weighted, _mm_add_epi32(_mm_madd_epi16(_mm_unpacklo_epi8(v, zero), w_lo),
                                              _mm_madd_epi16(_mm_unpackhi_epi8(v, zero), w_hi)));
  }
  alignas(16) std::uint32_t lanes[4];
  _mm_store_si128(reinterpret_cast<__m128i*>(lanes), weighted);
  t += lanes[0] + lanes[1] + lanes[2] + lanes[3];
#endif
  for (; i < n; ++i) {
    s0 += p[i];
    t += static_cast<std::uint32_t>(i) * p[i];
  }
  const std::uint32_t b = static_cast<std::uint32_t>(n) * s0 - t;
  return static_cast<std::uint16_t>((s0 & 0xFF) << 8 | (b & 0xFF));
}

// Sum of n bytes modulo 2^32 (callers reduce it), 16 bytes at a time with SSE2 where available.
inline std::uint32_t ByteSum(const std::uint8_t* p, std::size_t n) {
  std::uint32_t s = 0;
  std::size_t i = 0;
#if defined(__SSE2__)
  const __m128i zero = _mm_setzero_si128();
  __m128i acc = zero;
  for (; i + 16 <= n; i += 16) {
    acc = _mm_add_epi64(
        acc, _mm_sad_epu8(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p + i)), zero));
  }
  s = static_cast<std::uint32_t>(_mm_cvtsi128_si32(acc)) +
      static_cast<std::uint32_t>(_mm_cvtsi128_si32(_mm_unpackhi_epi64(acc, acc)));
#endif
  for (; i < n; ++i) s += p[i];
  return s;
}

// Legacy GX2/GX3-25: sum of all bytes modulo 65536 (sent big-endian).
std::uint16_t Gx2Checksum(std::span<const std::uint8_t> bytes);

// Xbus: the byte that makes the sum of everything after the preamble zero modulo 256. `bytes`
// starts at BID and ends at the last data byte.
std::uint8_t XbusChecksum(std::span<const std::uint8_t> bytes);

}  // namespace turncal::drivers
