#pragma once
// A fixed pool of worker threads running queued tasks (private to the service).

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace softshell::service::internal {

class TaskPool {
 public:
  explicit TaskPool(int threads) {
    size_ = static_cast<size_t>(std::max(1, threads));
    for (size_t i = 0; i < size_; ++i) workers_.emplace_back([this] { run(); });
  }
  ~TaskPool() { shutdown(); }
  TaskPool(const TaskPool&) = delete;
  TaskPool& operator=(const TaskPool&) = delete;

  // Queues a task. After shutdown() began, the task runs on the calling thread (tasks are
  // written to notice the shutdown and finish quickly), so nothing is ever dropped.
  void submit(std::function<void()> task) {
    {
      std::lock_guard lock(mu_);
      if (!stopping_) {
        tasks_.push_back(std::move(task));
        ++queued_;
        cv_.notify_one();
        return;
      }
    }
    task();
  }

  // Runs what is queued, then joins the workers. Idempotent.
  // Must not be called from one of the pool's own tasks.
  void shutdown() {
    std::lock_guard join_lock(join_mu_);  // serializes concurrent shutdown() calls
    {
      std::lock_guard lock(mu_);
      stopping_ = true;
    }
    cv_.notify_all();
    for (auto& t : workers_) {
      if (t.joinable()) t.join();
    }
  }

  size_t queued() const {
    std::lock_guard lock(mu_);
    return queued_;
  }
  size_t size() const { return size_; }

 private:
  void run() {
    for (;;) {
      std::function<void()> task;
      {
        std::unique_lock lock(mu_);
        cv_.wait(lock, [&] { return stopping_ || !tasks_.empty(); });
        if (tasks_.empty()) return;
        task = std::move(tasks_.front());
        tasks_.pop_front();
        --queued_;
      }
      task();
    }
  }

  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> tasks_;
  size_t queued_ = 0;
  bool stopping_ = false;
  std::mutex join_mu_;
  std::vector<std::thread> workers_;  // only touched by the constructor and shutdown()
  size_t size_ = 0;
};

}  // namespace softshell::service::internal
