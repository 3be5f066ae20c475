#include "daemon/device/transport_link.h"

#include <boost/asio/post.hpp>
#include <future>
#include <memory>

namespace turncal::daemon {

TransportLink::TransportLink(boost::asio::io_context& io, drivers::Transport* transport)
    : io_(io), transport_(transport) {}

void TransportLink::Deliver(std::span<const std::uint8_t> bytes) {
  {
    std::lock_guard lock(mutex_);
    received_.insert(received_.end(), bytes.begin(), bytes.end());
    // A device streaming into a dialogue that is not reading: keep the newest bytes.
    while (received_.size() > kMaxQueued) received_.pop_front();
  }
  arrived_.notify_all();
}

void TransportLink::Close(const std::string& why) {
  {
    std::lock_guard lock(mutex_);
    if (closed_) return;
    closed_ = true;
    why_ = why;
  }
  arrived_.notify_all();
}

bool TransportLink::Write(std::span<const std::uint8_t> bytes, std::string* error) {
  {
    std::lock_guard lock(mutex_);
    if (closed_) {
      if (error) *error = why_;
      return false;
    }
  }
  struct Outcome {
    bool ok = false;
    std::string error;
  };
  auto done = std::make_shared<std::promise<Outcome>>();
  auto result = done->get_future();
  std::vector<std::uint8_t> copy(bytes.begin(), bytes.end());
  boost::asio::post(io_, [this, done, copy = std::move(copy)] {
    Outcome o;
    o.ok = transport_->Write(copy, &o.error);
    done->set_value(std::move(o));
  });
  // The loop answers within one turn; a loop that does not (it is stopping) fails the write.
  if (result.wait_for(std::chrono::seconds(2)) != std::future_status::ready) {
    if (error) *error = transport_->Describe() + ": the event loop did not take the write";
    return false;
  }
  Outcome o = result.get();
  if (!o.ok && error) *error = o.error;
  return o.ok;
}

long TransportLink::Read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout,
                         std::string* error) {
  std::unique_lock lock(mutex_);
  arrived_.wait_for(lock, timeout, [this] { return closed_ || !received_.empty(); });
  if (received_.empty()) {
    if (closed_) {
      if (error) *error = why_;
      return -1;
    }
    return 0;
  }
  const std::size_t n = std::min(buffer.size(), received_.size());
  std::copy_n(received_.begin(), n, buffer.begin());
  received_.erase(received_.begin(), received_.begin() + static_cast<long>(n));
  return static_cast<long>(n);
}

}  // namespace turncal::daemon
