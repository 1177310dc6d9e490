// Executor (softshell/executor.h): parallel_for covers every item once, finishes when the pool is
// busy or nested, passes exceptions on; ThreadPool runs every posted task, also at shutdown.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <future>
#include <stdexcept>
#include <thread>
#include <vector>

#include "softshell/executor.h"

namespace softshell {
namespace {

TEST(Executor, ParallelForCallsEveryItemOnce) {
  ThreadPool pool(3);
  std::vector<std::atomic<int>> hits(1000);
  pool.parallel_for(0, 1000, [&](int64_t i) { hits[static_cast<size_t>(i)]++; });
  for (const auto& h : hits) EXPECT_EQ(h.load(), 1);
  pool.parallel_for(5, 5, [&](int64_t) { FAIL() << "empty range"; });
}

TEST(Executor, ParallelForFinishesWhenEveryWorkerIsBusy) {
  ThreadPool pool(2);
  std::promise<void> release;
  std::shared_future<void> released = release.get_future().share();
  std::atomic<int> blocked{0};
  for (int i = 0; i < 2; ++i) {
    pool.post([&, released] {
      ++blocked;
      released.wait();
    });
  }
  while (blocked.load() < 2) std::this_thread::yield();
  // Both workers wait; the caller does all the work itself.
  std::atomic<int> sum{0};
  pool.parallel_for(0, 100, [&](int64_t i) { sum += static_cast<int>(i); });
  EXPECT_EQ(sum.load(), 4950);
  release.set_value();
}

TEST(Executor, NestedParallelForDoesNotDeadlock) {
  ThreadPool pool(2);
  std::atomic<int> count{0};
  pool.parallel_for(0, 8, [&](int64_t) { pool.parallel_for(0, 8, [&](int64_t) { ++count; }); });
  EXPECT_EQ(count.load(), 64);
}

TEST(Executor, ParallelForRethrowsTheFirstExceptionAndSkipsTheRest) {
  ThreadPool pool(2);
  std::atomic<int> ran{0};
  // Item 0 (the caller's first) throws at once; every other item takes 1 ms. Without skipping,
  // the helper alone would run ~2000 of them (2 s); with it, only what it started before the
  // failure was seen (a thread would have to stall for a second to reach the bound).
  EXPECT_THROW(pool.parallel_for(0, 2000,
                                 [&](int64_t i) {
                                   ++ran;
                                   if (i == 0) throw std::runtime_error("item 0");
                                   std::this_thread::sleep_for(std::chrono::milliseconds(1));
                                 }),
               std::runtime_error);
  EXPECT_LT(ran.load(), 1000);
}

TEST(Executor, MaxWorkersBoundsTheThreads) {
  ThreadPool pool(4);
  std::atomic<int> running{0}, most{0};
  pool.parallel_for(0, 64, [&](int64_t) {
    const int now = ++running;
    for (int seen = most.load(); now > seen && !most.compare_exchange_weak(seen, now);) {}
    std::this_thread::sleep_for(std::chrono::microseconds(200));
    --running;
  }, 2);
  EXPECT_LE(most.load(), 2);
}

TEST(Executor, ThreadPoolRunsEveryPostedTaskEvenAtShutdown) {
  std::atomic<int> done{0};
  {
    ThreadPool pool(1);
    for (int i = 0; i < 100; ++i) pool.post([&] { ++done; });
    pool.shutdown();
    pool.post([&] { ++done; });  // after shutdown: runs on this thread
  }
  EXPECT_EQ(done.load(), 101);
}

TEST(Executor, InlineAndDefault) {
  InlineExecutor inline_executor;
  int order = 0;
  inline_executor.post([&] { order = 1; });
  EXPECT_EQ(order, 1);
  EXPECT_GE(default_executor()->concurrency(), 1);
  EXPECT_EQ(default_executor().get(), default_executor().get());
}

}  // namespace
}  // namespace softshell
