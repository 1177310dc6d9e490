#pragma once
// Tasks of one kind (precomputations, solves) run on the host's Executor, at most `limit` at
// once, with a shutdown that waits for every queued and running one (private to the service).
//
// The queue posts one runner per free slot; a runner takes tasks until the queue is empty, so
// the executor sees at most `limit` of this queue's runners and never a blocked thread.

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>

#include "softshell/executor.h"

namespace softshell::service::internal {

class TaskQueue {
 public:
  TaskQueue(std::shared_ptr<Executor> executor, int limit)
      : executor_(std::move(executor)), limit_(static_cast<size_t>(std::max(1, limit))) {}
  ~TaskQueue() { shutdown(); }
  TaskQueue(const TaskQueue&) = delete;
  TaskQueue& operator=(const TaskQueue&) = delete;

  // Queues a task. After shutdown() began, the task runs on the calling thread (tasks are
  // written to notice the shutdown and finish quickly), so nothing is ever dropped. Callers hold
  // no lock the task takes.
  void submit(std::function<void()> task) {
    bool post_runner = false, run_here = false;
    {
      std::lock_guard lock(mu_);
      if (stopping_) {
        run_here = true;
      } else {
        tasks_.push_back(std::move(task));
        if (runners_ < limit_) {
          ++runners_;
          post_runner = true;
        }
      }
    }
    if (run_here) task();
    if (post_runner) executor_->post([this] { drain(); });
  }

  // Stops taking tasks and waits until the queued and running ones finished. Idempotent; must not
  // be called from one of the queue's own tasks.
  void shutdown() {
    std::unique_lock lock(mu_);
    stopping_ = true;
    idle_.wait(lock, [&] { return runners_ == 0 && tasks_.empty(); });
  }

 private:
  void drain() {
    for (;;) {
      std::function<void()> task;
      {
        std::lock_guard lock(mu_);
        if (tasks_.empty()) {
          --runners_;
          // Notified under the lock: once it is released, shutdown() may return and the queue
          // be destroyed; this runner touches nothing after that.
          if (runners_ == 0) idle_.notify_all();
          return;
        }
        task = std::move(tasks_.front());
        tasks_.pop_front();
      }
      task();
    }
  }

  std::shared_ptr<Executor> executor_;
  const size_t limit_;
  std::mutex mu_;
  std::condition_variable idle_;
  std::deque<std::function<void()>> tasks_;
  size_t runners_ = 0;  // runners posted and not finished
  bool stopping_ = false;
};

}  // namespace softshell::service::internal
