// replay:FILE[?speed=X|max]: a capture's received bytes (device 0) and events, at their recorded
// times divided by the speed, or as fast as the io_context runs them.
#include <fmt/format.h>

#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <fstream>
#include <memory>

#include "drivers/capture/tcap.h"
#include "drivers/transport/transport_impl.h"

namespace turncal::drivers {

namespace {

class ReplayTransport final : public Transport {
 public:
  ReplayTransport(boost::asio::io_context& io, std::string file, double speed,
                  std::vector<CaptureRecord> records)
      : io_(io), file_(std::move(file)), speed_(speed), records_(std::move(records)), timer_(io) {}
  // A handler already queued (a posted Deliver, a timer that expired before it was cancelled)
  // may run after the transport is gone: it checks this first (ThreadSanitizer found the
  // use after free when turncald stopped during a replay).
  ~ReplayTransport() override { *alive_ = false; }

  void Start(DataHandler on_data, StatusHandler on_status) override {
    on_data_ = std::move(on_data);
    on_status_ = std::move(on_status);
    next_ = 0;
    stopped_ = false;
    start_ns_ = MonotonicNowNs();
    ++counters_.opens;
    if (on_status_) {
      on_status_(TransportStatus::kOpened,
                 fmt::format("{} opened ({} records, speed {})", Describe(), records_.size(),
                             speed_ > 0 ? fmt::format("{}x", speed_) : std::string("max")));
    }
    Schedule();
  }
  void SetEventHandler(EventHandler on_event) override { on_event_ = std::move(on_event); }
  bool Write(std::span<const std::uint8_t> bytes, std::string*) override {
    counters_.bytes_written += bytes.size();  // a replayed device does not listen
    return true;
  }
  void Stop() override {
    stopped_ = true;
    timer_.cancel();
    if (on_status_) on_status_(TransportStatus::kStopped, Describe() + " stopped");
  }
  bool is_open() const override { return !stopped_ && next_ < records_.size(); }
  std::string Describe() const override { return "replay:" + file_; }
  const TransportCounters& counters() const override { return counters_; }

 private:
  void Schedule() {
    if (stopped_) return;
    if (next_ >= records_.size()) {
      if (on_status_) on_status_(TransportStatus::kFinished, Describe() + " reached its end");
      return;
    }
    if (speed_ <= 0) {
      boost::asio::post(io_, [this, alive = alive_] {
        if (*alive) Deliver();
      });
      return;
    }
    const auto due =
        start_ns_ + static_cast<std::int64_t>(static_cast<double>(records_[next_].t_ns) / speed_);
    timer_.expires_after(
        std::chrono::nanoseconds(std::max<std::int64_t>(0, due - MonotonicNowNs())));
    timer_.async_wait([this, alive = alive_](const boost::system::error_code& ec) {
      if (!ec && *alive) Deliver();
    });
  }

  void Deliver() {
    if (stopped_ || next_ >= records_.size()) return;
    const CaptureRecord& r = records_[next_++];
    // Times as recorded, so a replay at any speed gives the pipeline the original timing.
    const auto t = static_cast<std::int64_t>(r.t_ns);
    if (r.type == RecordType::kReceived && r.device == 0) {
      counters_.bytes_read += r.payload.size();
      on_data_(r.payload, t);
    } else if (r.type == RecordType::kEvent && on_event_) {
      on_event_(std::string(r.payload.begin(), r.payload.end()), t);
    }
    Schedule();
  }

  boost::asio::io_context& io_;
  std::string file_;
  double speed_;
  std::vector<CaptureRecord> records_;
  boost::asio::steady_timer timer_;
  DataHandler on_data_;
  StatusHandler on_status_;
  EventHandler on_event_;
  std::size_t next_ = 0;
  std::int64_t start_ns_ = 0;
  bool stopped_ = false;
  TransportCounters counters_;
  std::shared_ptr<bool> alive_ = std::make_shared<bool>(true);
};

}  // namespace

std::unique_ptr<Transport> MakeReplayTransport(boost::asio::io_context& io, std::string file,
                                               double speed, std::string* error) {
  std::ifstream in(file, std::ios::binary);
  if (!in) {
    if (error) *error = "cannot open '" + file + "'";
    return nullptr;
  }
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                                  std::istreambuf_iterator<char>());
  std::vector<CaptureRecord> records;
  if (LooksLikeCapture(bytes)) {
    CaptureReader reader;
    if (!reader.Parse(std::move(bytes), error)) return nullptr;
    CaptureRecord r;
    while (reader.Next(&r)) records.push_back(r);
    if (!reader.error().empty()) {
      if (error) *error = file + ": " + reader.error();
      return nullptr;
    }
  } else {
    // A raw stream: all of it at once, at time 0.
    records.push_back({RecordType::kReceived, 0, 0, std::move(bytes)});
  }
  return std::make_unique<ReplayTransport>(io, std::move(file), speed, std::move(records));
}

}  // namespace turncal::drivers
