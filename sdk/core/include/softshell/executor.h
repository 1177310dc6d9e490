#pragma once
/// \file
/// \brief `Executor`: the host owns the threads. softshell runs its background and parallel work
/// (precomputation, solves, the Bullet bridge's sends, RemoteSession's requests) on an executor the
/// host gives it, as Jolt's JobSystem and Box2D's enqueueTask do; without one, on a shared default
/// pool. The C ABI adapts a task callback to this interface.

#include <cstdint>
#include <functional>
#include <memory>

namespace softshell {

/// Runs tasks on threads the host controls.
///
/// Thread-safety: every member may be called from any thread, including from inside a task.
class Executor {
 public:
  virtual ~Executor() = default;

  /// Runs `task` soon, on some thread of the executor. Must not block waiting for the task. Tasks
  /// must not throw (they catch what they raise). After the executor began shutting down, an
  /// implementation may run the task on the calling thread instead; it never drops one.
  virtual void post(std::function<void()> task) = 0;

  /// How many tasks run at once at most (>= 1): how far `parallel_for` splits its work.
  virtual int concurrency() const = 0;

  /// Calls fn(i) for every i in [begin, end) and returns when all calls have finished. The
  /// calling thread works too, so this finishes even when every executor thread is busy (no
  /// deadlock from nesting). Items are handed out one by one and run in no fixed order: fn must
  /// write only to item i's output. At most `max_workers` threads take part (<= 0: concurrency()).
  /// The first exception thrown by fn is rethrown here; the items not started yet are skipped.
  void parallel_for(int64_t begin, int64_t end, const std::function<void(int64_t)>& fn, int max_workers = 0);
};

/// A fixed pool of worker threads (what `default_executor()` is).
class ThreadPool final : public Executor {
 public:
  /// `threads` <= 0: std::thread::hardware_concurrency().
  explicit ThreadPool(int threads = 0);
  /// Runs the tasks still queued, then joins the workers.
  ~ThreadPool() override;
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  void post(std::function<void()> task) override;
  int concurrency() const override;
  /// Tasks queued and not started.
  size_t queued() const;
  /// Stops taking tasks (later ones run on the posting thread), runs what is queued and joins the
  /// workers. Idempotent; must not be called from one of the pool's own tasks.
  void shutdown();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Runs every task at once on the posting thread (concurrency 1): deterministic single-threaded
/// hosts and tests.
class InlineExecutor final : public Executor {
 public:
  void post(std::function<void()> task) override { task(); }
  int concurrency() const override { return 1; }
};

/// The process-wide pool used where the host gave no executor (hardware_concurrency threads,
/// created on first use, joined at exit).
std::shared_ptr<Executor> default_executor();

}  // namespace softshell
