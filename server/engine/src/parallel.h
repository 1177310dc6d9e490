#pragma once
// A minimal fork-join loop for the engine's per-face work (private).

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace softshell::engine::internal {

/// Number of worker threads for a requested count (0 = hardware concurrency).
inline int resolve_threads(int requested) {
  if (requested > 0) return requested;
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

/// Calls fn(i) for i in [begin, end) on `threads` threads (the caller's thread is one of them).
/// Items are handed out one by one, so the order of calls is not fixed: fn must write only to
/// its own item's output. The first exception thrown is rethrown after all threads stop.
template <class Fn>
void parallel_for(int64_t begin, int64_t end, int threads, Fn&& fn) {
  if (end <= begin) return;
  const int workers = static_cast<int>(std::min<int64_t>(threads, end - begin));
  std::atomic<int64_t> next{begin};
  std::atomic<bool> failed{false};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto work = [&] {
    try {
      for (int64_t i = next++; i < end && !failed.load(std::memory_order_relaxed); i = next++) fn(i);
    } catch (...) {
      std::lock_guard lock(error_mutex);
      if (!error) error = std::current_exception();
      failed = true;
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < workers; ++t) pool.emplace_back(work);
  work();
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace softshell::engine::internal
