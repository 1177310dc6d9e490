#include "softshell/executor.h"

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace softshell {

// ---------------------------------------------------------------------------------------------
// parallel_for: the caller and up to max_workers - 1 posted helpers pull items from one counter.
// The shared state lives in a shared_ptr: a helper that starts late (after every item is done)
// touches only that state, never `fn` or the caller's stack.

namespace {

struct ForState {
  std::atomic<int64_t> next;
  int64_t end;
  const std::function<void(int64_t)>* fn;
  std::atomic<bool> failed{false};
  std::mutex mu;
  std::condition_variable cv;
  int64_t finished = 0;  // items done or skipped (under mu)
  std::exception_ptr error;

  ForState(int64_t begin, int64_t end_, const std::function<void(int64_t)>* f) : next(begin), end(end_), fn(f) {}

  // Works until no item is left; returns after reporting what it did.
  void work() {
    int64_t done = 0;
    std::exception_ptr caught;
    for (int64_t i = next++; i < end; i = next++) {
      if (!failed.load(std::memory_order_relaxed)) {
        try {
          (*fn)(i);
        } catch (...) {
          if (!caught) caught = std::current_exception();
          failed = true;
        }
      }
      ++done;
    }
    if (done == 0) return;
    std::lock_guard lock(mu);
    if (caught && !error) error = caught;
    finished += done;
    cv.notify_all();
  }
};

}  // namespace

void Executor::parallel_for(int64_t begin, int64_t end, const std::function<void(int64_t)>& fn, int max_workers) {
  if (end <= begin) return;
  const int64_t count = end - begin;
  const int workers = static_cast<int>(std::min<int64_t>(max_workers > 0 ? max_workers : concurrency(), count));
  if (workers <= 1) {
    for (int64_t i = begin; i < end; ++i) fn(i);
    return;
  }
  auto state = std::make_shared<ForState>(begin, end, &fn);
  for (int w = 1; w < workers; ++w) post([state] { state->work(); });
  state->work();
  std::unique_lock lock(state->mu);
  state->cv.wait(lock, [&] { return state->finished == count; });
  if (state->error) std::rethrow_exception(state->error);
}

// ---------------------------------------------------------------------------------------------
// ThreadPool

struct ThreadPool::Impl {
  mutable std::mutex mu;
  std::condition_variable cv;
  std::deque<std::function<void()>> tasks;
  bool stopping = false;
  std::mutex join_mu;  // serializes shutdown()
  std::vector<std::thread> workers;
  int size = 1;

  void run() {
    for (;;) {
      std::function<void()> task;
      {
        std::unique_lock lock(mu);
        cv.wait(lock, [&] { return stopping || !tasks.empty(); });
        if (tasks.empty()) return;
        task = std::move(tasks.front());
        tasks.pop_front();
      }
      task();
    }
  }
};

ThreadPool::ThreadPool(int threads) : impl_(std::make_unique<Impl>()) {
  impl_->size = threads > 0 ? threads : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  for (int i = 0; i < impl_->size; ++i) impl_->workers.emplace_back([impl = impl_.get()] { impl->run(); });
}

ThreadPool::~ThreadPool() { shutdown(); }

void ThreadPool::post(std::function<void()> task) {
  {
    std::lock_guard lock(impl_->mu);
    if (!impl_->stopping) {
      impl_->tasks.push_back(std::move(task));
      impl_->cv.notify_one();
      return;
    }
  }
  task();
}

int ThreadPool::concurrency() const { return impl_->size; }

size_t ThreadPool::queued() const {
  std::lock_guard lock(impl_->mu);
  return impl_->tasks.size();
}

void ThreadPool::shutdown() {
  std::lock_guard join_lock(impl_->join_mu);
  {
    std::lock_guard lock(impl_->mu);
    impl_->stopping = true;
  }
  impl_->cv.notify_all();
  for (auto& t : impl_->workers) {
    if (t.joinable()) t.join();
  }
}

std::shared_ptr<Executor> default_executor() {
  static const std::shared_ptr<Executor> pool = std::make_shared<ThreadPool>();
  return pool;
}

}  // namespace softshell
