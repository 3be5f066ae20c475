#pragma once
// One thread that runs the station's pose updates (calibrator solves, data observability, gate)
// off the event loop, in order, and posts each one's completion back to the loop: the solves of
// 8 devices at one pose take hundreds of milliseconds together, and sample intake must not wait
// for them (issue "The daemon"; measured in docs/PERFORMANCE.md).

#include <boost/asio/io_context.hpp>
#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>

namespace turncal::daemon {

class SolveWorker {
 public:
  explicit SolveWorker(boost::asio::io_context& io);
  ~SolveWorker();  // finishes queued work, then joins

  // `work` on the worker thread, then `done` on the io_context.
  void Post(std::function<void()> work, std::function<void()> done);
  // Blocks until every posted work has run (the station is about to be replaced).
  void Drain();

  // The longest work so far, and the last (written by the worker under the mutex: read under it
  // too; ThreadSanitizer found the unlocked reads of `status`).
  double longest_ms() const {
    std::lock_guard lock(mutex_);
    return longest_ms_;
  }
  double last_ms() const {
    std::lock_guard lock(mutex_);
    return last_ms_;
  }
  std::size_t queued() const;

 private:
  void Loop();

  boost::asio::io_context& io_;
  mutable std::mutex mutex_;
  std::condition_variable wake_, idle_;
  std::deque<std::pair<std::function<void()>, std::function<void()>>> queue_;
  bool running_ = false;  // a work is executing
  bool stop_ = false;
  double longest_ms_ = 0, last_ms_ = 0;
  std::thread thread_;
};

}  // namespace turncal::daemon
