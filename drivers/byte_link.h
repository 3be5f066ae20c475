#pragma once
// What a device dialogue needs from a transport: write bytes, read what has arrived (waiting up to
// a timeout), and a monotonic clock. Serial ports, ptys, TCP and replay files implement it (issue
// "Transports"); tests implement it with a scripted device.

#include <chrono>
#include <cstdint>
#include <span>
#include <string>

namespace turncal::drivers {

class ByteLink {
 public:
  virtual ~ByteLink() = default;
  // False with a message when the bytes could not all be written (unplugged device, ...).
  virtual bool Write(std::span<const std::uint8_t> bytes, std::string* error) = 0;
  // Up to buffer.size() received bytes, waiting at most `timeout` for the first; 0 on timeout,
  // -1 with a message on failure.
  virtual long Read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout,
                    std::string* error) = 0;
  // Monotonic time, nanoseconds.
  virtual std::int64_t NowNs() = 0;
};

}  // namespace turncal::drivers
