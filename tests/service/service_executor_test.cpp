// The service on the host's threads (ServiceOptions::executor): its precomputations and solves
// run as tasks of the given executor, at most precompute_jobs + solve_threads at once, with the
// same answers as on the service's own pool; shutdown waits for what was queued.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <thread>
#include <vector>

#include "server_test_support.h"
#include "softshell/service/service.h"

namespace softshell::service {
namespace {

using test::exact_grid;
using test::exact_material;
using test::pinned_push;
using std::chrono::milliseconds;

// A host executor: a pool that counts the tasks it ran and the most that ran at once.
class CountingExecutor final : public Executor {
 public:
  explicit CountingExecutor(int threads) : pool_(threads) {}
  void post(std::function<void()> task) override {
    posted.fetch_add(1);
    pool_.post([this, task = std::move(task)] {
      const int now = running.fetch_add(1) + 1;
      int seen = most.load();
      while (now > seen && !most.compare_exchange_weak(seen, now)) {
      }
      task();
      running.fetch_sub(1);
    });
  }
  int concurrency() const override { return pool_.concurrency(); }

  std::atomic<int> posted{0}, running{0}, most{0};

 private:
  ThreadPool pool_;
};

ServiceOptions options_on(std::shared_ptr<Executor> executor) {
  ServiceOptions o;
  o.precompute_threads = 1;
  o.solve_threads = 2;
  o.precompute_jobs = 1;
  o.store_bytes = size_t{256} << 20;
  o.cache_bytes = size_t{64} << 20;
  o.executor = std::move(executor);
  // Keep the precomputation's own parallel work off the host executor here, so that the count
  // below is the service's tasks only.
  o.precompute.executor = std::make_shared<InlineExecutor>();
  return o;
}

std::vector<Vec3> solved(Service& s, const GeomId& id, int k) {
  auto r = s.deform(id, pinned_push(k)).get();
  EXPECT_TRUE(r) << r.error().message;
  return r ? (*r)->positions : std::vector<Vec3>{};
}

TEST(ServiceExecutorTest, PrecomputationsAndSolvesRunOnTheHostsThreadsWithinTheLimits) {
  auto host = std::make_shared<CountingExecutor>(8);
  std::vector<std::vector<Vec3>> answers(12);
  {
    Service s(options_on(host));
    auto up = s.upload(exact_grid(), exact_material());
    ASSERT_TRUE(up) << up.error().message;
    // Twelve requests from four threads at once: solves queue behind the precomputation.
    std::vector<std::thread> clients;
    for (int c = 0; c < 4; ++c) {
      clients.emplace_back([&, c] {
        for (int k = c; k < 12; k += 4) answers[static_cast<size_t>(k)] = solved(s, up->id, k + 1);
      });
    }
    for (auto& t : clients) t.join();
    EXPECT_EQ(s.result_ids(up->id)->size(), 12u);
  }
  EXPECT_GE(host->posted.load(), 2) << "the precomputation and the solves were tasks of the host's executor";
  EXPECT_LE(host->most.load(), 3) << "at most precompute_jobs + solve_threads of the service's tasks at once";

  // The same answers as on the service's own pool.
  ServiceOptions own = options_on(nullptr);
  Service reference(own);
  auto up = reference.upload(exact_grid(), exact_material());
  ASSERT_TRUE(up);
  for (int k = 0; k < 12; ++k) {
    const std::vector<Vec3> expected = solved(reference, up->id, k + 1);
    ASSERT_EQ(answers[static_cast<size_t>(k)].size(), expected.size());
    for (size_t v = 0; v < expected.size(); ++v) {
      EXPECT_LT((answers[static_cast<size_t>(k)][v] - expected[v]).norm(), 1e-12) << "request " << k << " point " << v;
    }
  }
}

TEST(ServiceExecutorTest, AnInlineExecutorRunsEverythingOnTheCallersThread) {
  Service s(options_on(std::make_shared<InlineExecutor>()));
  auto up = s.upload(exact_grid(), exact_material());
  ASSERT_TRUE(up) << up.error().message;
  // The precomputation ran inside upload().
  auto info = s.info(up->id);
  ASSERT_TRUE(info);
  EXPECT_EQ(info->status, GeometryStatus::kReady);
  auto future = s.deform(up->id, pinned_push(1));
  ASSERT_EQ(future.wait_for(milliseconds(0)), std::future_status::ready) << "solved inside deform()";
  ASSERT_TRUE(future.get());
}

TEST(ServiceExecutorTest, ShutdownAnswersWhatWasQueuedOnTheHostsThreads) {
  auto host = std::make_shared<CountingExecutor>(1);
  std::atomic<int> answered{0};
  {
    Service s(options_on(host));
    auto up = s.upload(test::make_grid(24, 24), exact_material());
    ASSERT_TRUE(up);
    for (int k = 1; k <= 20; ++k) {
      s.deform(up->id, pinned_push(k, 24), [&](Result<ResultPtr>) { answered.fetch_add(1); });
    }
    s.shutdown();
    EXPECT_EQ(answered.load(), 20) << "every request answered (a result or the shutdown error) before shutdown returns";
    auto late = s.deform(up->id, pinned_push(1, 24));
    ASSERT_EQ(late.wait_for(milliseconds(0)), std::future_status::ready);
    const auto refused = late.get();
    ASSERT_FALSE(refused);
    EXPECT_EQ(refused.error().code, ErrorCode::kUnavailable);
  }
}

}  // namespace
}  // namespace softshell::service
