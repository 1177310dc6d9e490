#pragma once
// The I/O threads of the HTTP server (private to the HTTP layer): cpp-httplib runs every open
// connection on a task-queue thread; this queue creates them on demand up to a maximum and keeps
// them for reuse; a thread idle for `idle_exit` exits (down to kKeep threads), so a burst of
// clients does not leave hundreds of idle threads behind.
//
// Threads keep the default stack size: cpp-httplib routes with std::regex, whose matcher
// recurses once per character of the path (measured: an 8 KB URI, which the library accepts,
// needs more than 2 MiB of stack). Only the pages a thread touches count as memory, and event
// streams do not keep a thread (they are handed to the event writer).

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include "listener.h"

namespace softshell::http::internal {

class ConnectionThreads final : public httplib::TaskQueue {
 public:
  static constexpr size_t kKeep = 8;

  ConnectionThreads(size_t max_threads, std::chrono::milliseconds idle_exit, std::atomic<int>& busy,
                    std::atomic<int>& live);
  ~ConnectionThreads() override;

  void enqueue(std::function<void()> fn) override;
  void shutdown() override;

 private:
  void work();
  // Joins threads that left for idleness (they gave up the lock for good before their id became
  // visible here, so these joins return at once).
  void reap_locked();

  const size_t max_;
  const std::chrono::milliseconds idle_exit_;
  std::atomic<int>& busy_;
  std::atomic<int>& live_count_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> jobs_;
  std::vector<std::thread> threads_;     // every thread not joined yet
  std::vector<std::thread::id> exited_;  // threads that left for idleness, to join
  size_t live_ = 0;                      // threads running work()
  size_t idle_ = 0;
  bool stopping_ = false;
};

}  // namespace softshell::http::internal
