#pragma once
// Private: what the serial and TCP transports share: open with backoff, an asynchronous read
// loop, and a disconnect that schedules a reopen.

#include <fmt/format.h>
#include <boost/asio/steady_timer.hpp>

#include <array>
#include <memory>

#include "drivers/transport/transport.h"

namespace turncal::drivers {

template <class Stream>
class Reconnecting : public Transport {
 public:
  // A handler already queued (a read that completed, a timer that expired before it was
  // cancelled, an open's result) may run after the transport is gone: each checks this first.
  ~Reconnecting() override { *alive_ = false; }

  void Start(DataHandler on_data, StatusHandler on_status) override {
    on_data_ = std::move(on_data);
    on_status_ = std::move(on_status);
    stopped_ = false;
    delay_ = options_.reconnect_initial;
    TryOpen();
  }

  bool Write(std::span<const std::uint8_t> bytes, std::string* error) override {
    if (!stream_ || !stream_->is_open()) {
      if (error) *error = Describe() + " is not open";
      return false;
    }
    boost::system::error_code ec;
    boost::asio::write(*stream_, boost::asio::buffer(bytes.data(), bytes.size()), ec);
    if (ec) {
      if (error) *error = Describe() + ": write failed: " + ec.message();
      return false;
    }
    counters_.bytes_written += bytes.size();
    return true;
  }

  void Stop() override {
    stopped_ = true;
    timer_.cancel();
    Close();
    if (on_status_) on_status_(TransportStatus::kStopped, Describe() + " stopped");
  }

  bool is_open() const override { return stream_ && stream_->is_open(); }
  const TransportCounters& counters() const override { return counters_; }

 protected:
  Reconnecting(boost::asio::io_context& io, TransportOptions options)
      : io_(io), options_(options), timer_(io) {}

  virtual void CloseExtra() {}

  using OpenDone = std::function<void(std::unique_ptr<Stream> stream, const std::string& how,
                                      const std::string& error)>;
  // Starts opening the device; calls `done` with a stream and the backend's name, or with nullptr
  // and a message (possibly later, from the io_context).
  virtual void BeginOpen(OpenDone done) = 0;

  boost::asio::io_context& io_;
  TransportOptions options_;

 private:
  void TryOpen() {
    if (stopped_) return;
    BeginOpen([this, alive = alive_](std::unique_ptr<Stream> stream, const std::string& how,
                                     const std::string& error) {
      if (!*alive || stopped_) return;
      if (stream) {
        stream_ = std::move(stream);
        ++counters_.opens;
        delay_ = options_.reconnect_initial;
        if (on_status_) on_status_(TransportStatus::kOpened, Describe() + " opened (" + how + ")");
        Read();
        return;
      }
      ++counters_.open_failures;
      if (on_status_) {
        on_status_(TransportStatus::kOpenFailed,
                   fmt::format("{}: {}; retrying in {} ms", Describe(), error, delay_.count()));
      }
      Retry();
    });
  }

  void Retry() {
    timer_.expires_after(delay_);
    delay_ = std::min(delay_ * 2, options_.reconnect_max);
    timer_.async_wait([this, alive = alive_](const boost::system::error_code& ec) {
      if (!ec && *alive) TryOpen();
    });
  }

  void Read() {
    stream_->async_read_some(
        boost::asio::buffer(buffer_),
        [this, alive = alive_](const boost::system::error_code& ec, std::size_t n) {
          if (!*alive || ec == boost::asio::error::operation_aborted || stopped_) return;
          if (n > 0) {
            counters_.bytes_read += n;
            on_data_(std::span<const std::uint8_t>(buffer_.data(), n), MonotonicNowNs());
            if (stopped_ || !stream_) return;  // the handler stopped us
          }
          if (ec) {
            ++counters_.disconnects;
            Close();
            if (on_status_) {
              on_status_(TransportStatus::kDisconnected,
                         fmt::format("{}: device gone ({}); reopening in {} ms", Describe(),
                                     ec.message(), delay_.count()));
            }
            Retry();
            return;
          }
          Read();
        });
  }

  void Close() {
    if (stream_) {
      boost::system::error_code ignored;
      stream_->close(ignored);
      stream_.reset();
    }
    CloseExtra();
  }

  DataHandler on_data_;
  StatusHandler on_status_;
  boost::asio::steady_timer timer_;
  std::chrono::milliseconds delay_{100};
  std::unique_ptr<Stream> stream_;
  std::array<std::uint8_t, 4096> buffer_{};
  TransportCounters counters_;
  bool stopped_ = false;
  std::shared_ptr<bool> alive_ = std::make_shared<bool>(true);
};

}  // namespace turncal::drivers
