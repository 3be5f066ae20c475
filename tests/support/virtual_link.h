// The host's end of a byte link to a test device (a scripted one, or the device emulator of
// sim/device.h), on a virtual clock: the tests of the device dialogues (tests/drivers/
// dialogue_test.cc), the emulator (tests/sim/sim_device_test.cc), the stored write
// (tests/sim/mip_stored_write_test.cc) and the device writer (tests/daemon/device_writer_test.cc)
// share it. A test's link decides in Write what the device answers and Queue()s it; a read hands
// out what is queued (at most `max_chunk` bytes, 0.1 ms on the clock). When nothing is queued the
// device may stream meanwhile (StreamWhileIdle, 2 ms on the clock); otherwise the read waits out
// its timeout.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <limits>
#include <span>
#include <string>

#include "drivers/byte_link.h"

namespace turncal::testing_support {

class VirtualClockLink : public drivers::ByteLink {
 public:
  explicit VirtualClockLink(std::size_t max_chunk = std::numeric_limits<std::size_t>::max())
      : max_chunk_(max_chunk) {}

  long Read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout,
            std::string*) override {
    if (queued_.empty() && StreamWhileIdle()) now_ns_ += 2'000'000;
    if (queued_.empty()) {
      now_ns_ += std::chrono::duration_cast<std::chrono::nanoseconds>(timeout).count();
      return 0;
    }
    const std::size_t n = std::min({buffer.size(), queued_.size(), max_chunk_});
    for (std::size_t i = 0; i < n; ++i) {
      buffer[i] = queued_.front();
      queued_.pop_front();
    }
    now_ns_ += 100'000;
    return static_cast<long>(n);
  }
  std::int64_t NowNs() override { return now_ns_; }

 protected:
  // Called by a read that finds nothing queued: a streaming device queues data and answers true.
  virtual bool StreamWhileIdle() { return false; }
  void Queue(std::span<const std::uint8_t> bytes) {
    queued_.insert(queued_.end(), bytes.begin(), bytes.end());
  }

 private:
  std::size_t max_chunk_;
  std::deque<std::uint8_t> queued_;
  std::int64_t now_ns_ = 0;
};

}  // namespace turncal::testing_support
