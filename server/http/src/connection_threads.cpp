#include "connection_threads.h"

#include <algorithm>

namespace softshell::http::internal {

ConnectionThreads::ConnectionThreads(size_t max_threads, std::chrono::milliseconds idle_exit, std::atomic<int>& busy,
                                     std::atomic<int>& live)
    : max_(std::max<size_t>(1, max_threads)), idle_exit_(idle_exit), busy_(busy), live_count_(live) {}

ConnectionThreads::~ConnectionThreads() { shutdown(); }

void ConnectionThreads::enqueue(std::function<void()> fn) {
  std::lock_guard lock(mu_);
  reap_locked();
  jobs_.push_back(std::move(fn));
  // Every idle thread takes one job; jobs beyond them get a new thread while allowed.
  if (jobs_.size() > idle_ && live_ < max_) {
    ++live_;
    live_count_.store(static_cast<int>(live_));
    threads_.emplace_back([this] { work(); });
  } else {
    cv_.notify_one();
  }
}

void ConnectionThreads::shutdown() {
  std::vector<std::thread> threads;
  {
    std::lock_guard lock(mu_);
    stopping_ = true;
    threads.swap(threads_);
    exited_.clear();
  }
  cv_.notify_all();
  for (auto& t : threads) t.join();
}

void ConnectionThreads::work() {
  std::unique_lock lock(mu_);
  for (;;) {
    ++idle_;
    const bool woken = cv_.wait_for(lock, idle_exit_, [&] { return stopping_ || !jobs_.empty(); });
    --idle_;
    if (!woken && live_ > kKeep) {  // idle for long: leave (joined by a later enqueue)
      --live_;
      live_count_.store(static_cast<int>(live_));
      exited_.push_back(std::this_thread::get_id());
      return;
    }
    if (jobs_.empty()) {
      if (stopping_) return;
      continue;
    }
    auto fn = std::move(jobs_.front());
    jobs_.pop_front();
    lock.unlock();
    busy_.fetch_add(1);
    fn();
    busy_.fetch_sub(1);
    lock.lock();
  }
}

void ConnectionThreads::reap_locked() {
  for (const auto id : exited_) {
    auto it = std::find_if(threads_.begin(), threads_.end(), [&](const std::thread& t) { return t.get_id() == id; });
    if (it != threads_.end()) {
      it->join();
      threads_.erase(it);
    }
  }
  exited_.clear();
}

}  // namespace softshell::http::internal
