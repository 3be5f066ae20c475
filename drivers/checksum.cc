#include "drivers/checksum.h"

namespace turncal::drivers {

std::uint16_t MipChecksum(std::span<const std::uint8_t> bytes) {
  std::uint8_t a = 0, b = 0;
  for (std::uint8_t byte : bytes) {
    a = static_cast<std::uint8_t>(a + byte);
    b = static_cast<std::uint8_t>(b + a);
  }
  return static_cast<std::uint16_t>(a << 8 | b);
}

std::uint16_t Gx2Checksum(std::span<const std::uint8_t> bytes) {
  std::uint16_t sum = 0;
  for (std::uint8_t byte : bytes) sum = static_cast<std::uint16_t>(sum + byte);
  return sum;
}

std::uint8_t XbusChecksum(std::span<const std::uint8_t> bytes) {
  std::uint8_t sum = 0;
  for (std::uint8_t byte : bytes) sum = static_cast<std::uint8_t>(sum + byte);
  return static_cast<std::uint8_t>(-sum);
}

}  // namespace turncal::drivers
