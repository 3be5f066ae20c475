#include "daemon/service/solve_worker.h"

#include <boost/asio/post.hpp>
#include <chrono>

namespace turncal::daemon {

SolveWorker::SolveWorker(boost::asio::io_context& io) : io_(io), thread_([this] { Loop(); }) {}

SolveWorker::~SolveWorker() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void SolveWorker::Post(std::function<void()> work, std::function<void()> done) {
  {
    std::lock_guard lock(mutex_);
    queue_.emplace_back(std::move(work), std::move(done));
  }
  wake_.notify_one();
}

void SolveWorker::Drain() {
  std::unique_lock lock(mutex_);
  idle_.wait(lock, [this] { return queue_.empty() && !running_; });
}

std::size_t SolveWorker::queued() const {
  std::lock_guard lock(mutex_);
  return queue_.size() + (running_ ? 1 : 0);
}

void SolveWorker::Loop() {
  std::unique_lock lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stop_ || !queue_.empty(); });
    if (queue_.empty()) return;  // stopping, nothing left
    auto [work, done] = std::move(queue_.front());
    queue_.pop_front();
    running_ = true;
    lock.unlock();
    const auto t0 = std::chrono::steady_clock::now();
    work();
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    boost::asio::post(io_, std::move(done));
    lock.lock();
    last_ms_ = ms;
    longest_ms_ = std::max(longest_ms_, ms);
    running_ = false;
    if (queue_.empty()) idle_.notify_all();
  }
}

}  // namespace turncal::daemon
