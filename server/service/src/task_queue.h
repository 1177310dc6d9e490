#pragma once
// Tasks of one kind (precomputations, solves) run on the host's Executor, at most `limit` at
// once, with a shutdown that waits for every queued and running one (private to the service).
//
// The queue posts one runner per free slot; a runner takes tasks until the queue is empty, so
// the executor sees at most `limit` of this queue's runners and never a blocked thread.
//
// Fairness: tasks carry a key (the geometry they work for) and are taken round-robin over the
// keys with queued tasks, in each key's arrival order. A client that queues a hundred solves on
// one geometry delays another geometry's next solve by at most one task per slot, not by all.

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <unordered_map>

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
  void submit(std::function<void()> task, const void* key = nullptr) {
    bool post_runner = false, run_here = false;
    {
      std::lock_guard lock(mu_);
      if (stopping_) {
        run_here = true;
      } else {
        auto& queue = by_key_[key];
        if (queue.empty()) turns_.push_back(key);
        queue.push_back(std::move(task));
        ++queued_;
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
    idle_.wait(lock, [&] { return runners_ == 0 && queued_ == 0; });
  }

 private:
  void drain() {
    for (;;) {
      std::function<void()> task;
      {
        std::lock_guard lock(mu_);
        if (queued_ == 0) {
          --runners_;
          // Notified under the lock: once it is released, shutdown() may return and the queue
          // be destroyed; this runner touches nothing after that.
          if (runners_ == 0) idle_.notify_all();
          return;
        }
        // The key whose turn it is gives its oldest task and, if it has more, goes to the back.
        const void* key = turns_.front();
        turns_.pop_front();
        auto it = by_key_.find(key);
        if (it == by_key_.end() || it->second.empty()) continue;  // cannot happen: turns_ names queued keys
        task = std::move(it->second.front());
        it->second.pop_front();
        --queued_;
        if (it->second.empty()) {
          by_key_.erase(it);
        } else {
          turns_.push_back(key);
        }
      }
      task();
    }
  }

  std::shared_ptr<Executor> executor_;
  const size_t limit_;
  std::mutex mu_;
  std::condition_variable idle_;
  std::unordered_map<const void*, std::deque<std::function<void()>>> by_key_;  // keys with queued tasks
  std::deque<const void*> turns_;  // each key of by_key_ once, next turn first
  size_t queued_ = 0;
  size_t runners_ = 0;  // runners posted and not finished
  bool stopping_ = false;
};

}  // namespace softshell::service::internal
