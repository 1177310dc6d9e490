#pragma once
// One thread that ends hold leases when they lapse (private to the service).

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <thread>
#include <unordered_map>
#include <utility>
#include <vector>

namespace softshell::service::internal {

// Calls a lease's callback once its deadline has passed, unless the lease was rescheduled or
// cancelled first. Callbacks run on the timer's thread, without its lock; they must check that
// the lease they end is still the one that lapsed (a renewal may race with the expiry).
class LeaseTimer {
 public:
  using Clock = std::chrono::steady_clock;

  LeaseTimer() : thread_([this] { run(); }) {}
  ~LeaseTimer() { stop(); }
  LeaseTimer(const LeaseTimer&) = delete;
  LeaseTimer& operator=(const LeaseTimer&) = delete;

  // Sets (or moves) the deadline of a lease.
  void schedule(uint64_t lease, Clock::time_point deadline, std::function<void()> on_expiry) {
    {
      std::lock_guard lock(mu_);
      if (stopping_) return;
      if (auto it = when_.find(lease); it != when_.end()) queue_.erase({it->second, lease});
      when_[lease] = deadline;
      queue_.emplace(std::pair{deadline, lease}, std::move(on_expiry));
    }
    cv_.notify_one();
  }

  void cancel(uint64_t lease) {
    std::lock_guard lock(mu_);
    if (auto it = when_.find(lease); it != when_.end()) {
      queue_.erase({it->second, lease});
      when_.erase(it);
    }
  }

  size_t size() const {
    std::lock_guard lock(mu_);
    return queue_.size();
  }

  // Stops the thread; pending leases never fire. Idempotent.
  void stop() {
    {
      std::lock_guard lock(mu_);
      stopping_ = true;
      queue_.clear();
      when_.clear();
    }
    cv_.notify_one();
    std::lock_guard join(join_mu_);
    if (thread_.joinable()) thread_.join();
  }

 private:
  void run() {
    std::unique_lock lock(mu_);
    while (!stopping_) {
      if (queue_.empty()) {
        cv_.wait(lock);
        continue;
      }
      const auto next = queue_.begin()->first.first;
      if (Clock::now() < next) {
        cv_.wait_until(lock, next);
        continue;
      }
      std::vector<std::function<void()>> due;
      const auto now = Clock::now();
      while (!queue_.empty() && queue_.begin()->first.first <= now) {
        when_.erase(queue_.begin()->first.second);
        due.push_back(std::move(queue_.begin()->second));
        queue_.erase(queue_.begin());
      }
      lock.unlock();
      for (auto& fn : due) fn();
      lock.lock();
    }
  }

  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::map<std::pair<Clock::time_point, uint64_t>, std::function<void()>> queue_;
  std::unordered_map<uint64_t, Clock::time_point> when_;
  bool stopping_ = false;
  std::mutex join_mu_;
  std::thread thread_;  // last: started once everything above exists
};

}  // namespace softshell::service::internal
