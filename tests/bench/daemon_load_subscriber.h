// The load tool's subscribers (tests/bench/daemon_load.cc): a latency histogram, and a subscriber
// to corrected output that reads on its own thread and times every CORRECTED line from the
// daemon's read of its bytes (t_host_ns) to its receipt.
#pragma once

#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "daemon_load_probes.h"

namespace daemon_load {

// Latency histogram: 1 us buckets up to 100 ms, 100 us buckets up to 10 s, the rest counted
// with the maximum.

class Histogram {
 public:
  static constexpr std::size_t kFine = 100'000;            // 1 us each
  static constexpr std::size_t kBuckets = kFine + 99'000;  // then 100 us each
  static std::size_t Bucket(std::int64_t us) {
    const auto u = static_cast<std::size_t>(us);
    return u < kFine ? u : kFine + (u - kFine) / 100;
  }
  // The upper edge of a bucket, in ms.
  static double UpperMs(std::size_t i) {
    return i < kFine ? static_cast<double>(i + 1) / 1000.0
                     : static_cast<double>(kFine + (i - kFine + 1) * 100) / 1000.0;
  }
  Histogram() : counts_(kBuckets, 0) {}
  void Add(std::int64_t ns) {
    ++count_;
    max_ns_ = std::max(max_ns_, ns);
    if (ns < 0) {
      ++negative_;
      ns = 0;
    }
    const std::size_t b = Bucket(ns / 1000);
    if (b < kBuckets) {
      ++counts_[b];
    } else {
      ++over_;
    }
    sum_ns_ += static_cast<double>(ns);
  }
  void Merge(const Histogram& o) {
    for (std::size_t i = 0; i < kBuckets; ++i) counts_[i] += o.counts_[i];
    count_ += o.count_;
    over_ += o.over_;
    negative_ += o.negative_;
    max_ns_ = std::max(max_ns_, o.max_ns_);
    sum_ns_ += o.sum_ns_;
  }
  // this - earlier (an interval of a cumulative histogram); the maximum is not kept.
  Histogram Minus(const Histogram& earlier) const {
    Histogram h;
    for (std::size_t i = 0; i < kBuckets; ++i) h.counts_[i] = counts_[i] - earlier.counts_[i];
    h.count_ = count_ - earlier.count_;
    h.over_ = over_ - earlier.over_;
    h.negative_ = negative_ - earlier.negative_;
    h.sum_ns_ = sum_ns_ - earlier.sum_ns_;
    h.max_ns_ = -1;
    return h;
  }
  std::uint64_t count() const { return count_; }
  std::uint64_t negative() const { return negative_; }
  double max_ms() const { return static_cast<double>(max_ns_) / 1e6; }
  double mean_ms() const { return count_ ? sum_ns_ / static_cast<double>(count_) / 1e6 : 0; }
  // The q-quantile in ms (upper edge of its bucket); above 10 s: the maximum.
  double Quantile(double q) const {
    if (count_ == 0) return 0;
    const auto rank = static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(count_)));
    std::uint64_t seen = 0;
    for (std::size_t i = 0; i < kBuckets; ++i) {
      seen += counts_[i];
      if (seen >= rank && seen > 0) return UpperMs(i);
    }
    return max_ms();
  }
  // Fraction of samples above `ms`.
  double FractionAbove(double ms) const {
    if (count_ == 0) return 0;
    const std::size_t limit = Bucket(static_cast<std::int64_t>(ms * 1000.0));
    std::uint64_t above = over_;
    for (std::size_t i = limit; i < kBuckets; ++i) above += counts_[i];
    return static_cast<double>(above) / static_cast<double>(count_);
  }

 private:
  std::vector<std::uint32_t> counts_;
  std::uint64_t count_ = 0, over_ = 0, negative_ = 0;
  std::int64_t max_ns_ = 0;
  double sum_ns_ = 0;
};

class Subscriber {
 public:
  Subscriber(int index, int fd, std::atomic<bool>* measuring, std::atomic<bool>* stop)
      : index_(index), fd_(fd), measuring_(measuring), stop_(stop) {}
  ~Subscriber() {
    if (thread_.joinable()) thread_.join();
    if (fd_ >= 0) ::close(fd_);
  }
  void Start() {
    thread_ = std::thread([this] { Run(); });
  }
  void Join() {
    if (thread_.joinable()) thread_.join();
  }

  // Copies under the lock.
  Histogram Snapshot() {
    std::lock_guard lock(mutex_);
    return hist_;
  }
  struct Counters {
    std::uint64_t lines = 0, corrected = 0, dropped_notes = 0, dropped = 0, bytes = 0, errors = 0,
                  unparsed = 0;
    std::set<std::string> devices;  // seen before the measurement (warm-up)
    bool closed = false;
    std::string last_error;
  };
  Counters counters() {
    std::lock_guard lock(mutex_);
    return counters_;
  }
  int index() const { return index_; }

 private:
  void Run() {
    std::string buffer;
    std::vector<char> chunk(1 << 16);
    while (!stop_->load()) {
      pollfd p{fd_, POLLIN, 0};
      const int r = ::poll(&p, 1, 200);
      if (r <= 0) continue;
      const ssize_t n = ::recv(fd_, chunk.data(), chunk.size(), 0);
      const std::int64_t now = MonotonicNs();
      if (n <= 0) {
        if (n < 0 && errno == EINTR) continue;
        std::lock_guard lock(mutex_);
        counters_.closed = true;
        return;
      }
      buffer.append(chunk.data(), static_cast<std::size_t>(n));
      const bool measuring = measuring_->load();
      std::lock_guard lock(mutex_);
      if (measuring) counters_.bytes += static_cast<std::size_t>(n);
      std::size_t start = 0;
      for (auto nl = buffer.find('\n'); nl != std::string::npos; nl = buffer.find('\n', start)) {
        OnLine(std::string_view(buffer).substr(start, nl - start), now, measuring);
        start = nl + 1;
      }
      buffer.erase(0, start);
    }
  }

  void OnLine(std::string_view line, std::int64_t now, bool measuring) {
    static constexpr std::string_view kCorrected = "{\"class\":\"CORRECTED\"";
    static constexpr std::string_view kTime = "\"t_host_ns\":";
    static constexpr std::string_view kDevice = "\"device\":\"";
    static constexpr std::string_view kDropped = "{\"class\":\"DROPPED\"";
    if (measuring) ++counters_.lines;
    if (line.substr(0, kCorrected.size()) == kCorrected) {
      const auto t = line.find(kTime);
      if (t == std::string_view::npos) {
        ++counters_.unparsed;
        return;
      }
      const std::int64_t t_host = std::strtoll(line.data() + t + kTime.size(), nullptr, 10);
      if (measuring) {
        ++counters_.corrected;
        hist_.Add(now - t_host);
      } else {
        const auto d = line.find(kDevice);
        if (d != std::string_view::npos) {
          const auto begin = d + kDevice.size();
          const auto end = line.find('"', begin);
          if (end != std::string_view::npos) {
            counters_.devices.emplace(line.substr(begin, end - begin));
          }
        }
      }
      return;
    }
    if (line.substr(0, kDropped.size()) == kDropped) {
      const json j = json::parse(line, nullptr, false);
      if (measuring && !j.is_discarded()) {
        ++counters_.dropped_notes;
        counters_.dropped += j.value("count", 0ULL);
      }
      return;
    }
    if (line.find("\"class\":\"ERROR\"") != std::string_view::npos) {
      ++counters_.errors;
      counters_.last_error = std::string(line);
    }
  }

  int index_;
  int fd_;
  std::atomic<bool>* measuring_;
  std::atomic<bool>* stop_;
  std::thread thread_;
  std::mutex mutex_;
  Histogram hist_;
  Counters counters_;
};

}  // namespace daemon_load
