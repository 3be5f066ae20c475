#pragma once
// A ByteLink (drivers/byte_link.h) over a transport that the event loop reads: the device
// dialogues are synchronous (write, wait for the reply with a timeout), so they run on a worker
// thread while the loop goes on serving every other device and client. Bytes the transport
// delivers on the loop are handed over with Deliver(); writes are posted to the loop (the
// transport's stream is only touched there) and waited for.

#include <boost/asio/io_context.hpp>
#include <condition_variable>
#include <deque>
#include <mutex>

#include "drivers/byte_link.h"
#include "drivers/transport/transport.h"

namespace turncal::daemon {

class TransportLink final : public drivers::ByteLink {
 public:
  TransportLink(boost::asio::io_context& io, drivers::Transport* transport);

  // Loop thread: bytes the transport received.
  void Deliver(std::span<const std::uint8_t> bytes);
  // Any thread: the device went away or the daemon stops; the dialogue's next read or write
  // fails with `why`.
  void Close(const std::string& why);

  // Worker thread.
  bool Write(std::span<const std::uint8_t> bytes, std::string* error) override;
  long Read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout,
            std::string* error) override;
  std::int64_t NowNs() override { return drivers::MonotonicNowNs(); }

 private:
  boost::asio::io_context& io_;
  drivers::Transport* transport_;
  std::mutex mutex_;
  std::condition_variable arrived_;
  std::deque<std::uint8_t> received_;
  bool closed_ = false;
  std::string why_;
  static constexpr std::size_t kMaxQueued = 1 << 20;  // a dialogue reads far less than this
};

}  // namespace turncal::daemon
