// The service's task queue (server/service/src/task_queue.h): round-robin over the geometries
// with queued tasks, so one geometry's burst does not make another's next solve wait for all of
// it; nothing is dropped at shutdown.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "task_queue.h"

namespace softshell::service::internal {
namespace {

// An executor whose posted runners wait until the test runs them (deterministic order).
class ManualExecutor final : public Executor {
 public:
  void post(std::function<void()> task) override { posted.push_back(std::move(task)); }
  int concurrency() const override { return 1; }
  void run_all() {
    while (!posted.empty()) {
      auto task = std::move(posted.front());
      posted.erase(posted.begin());
      task();
    }
  }
  std::vector<std::function<void()>> posted;
};

TEST(TaskQueueTest, TasksAreTakenRoundRobinOverTheirKeys) {
  auto executor = std::make_shared<ManualExecutor>();
  std::vector<std::string> order;
  {
    TaskQueue queue(executor, 1);
    int a = 0, b = 0, c = 0;  // three geometries
    for (int i = 1; i <= 5; ++i) queue.submit([&, i] { order.push_back("a" + std::to_string(i)); }, &a);
    queue.submit([&] { order.push_back("b1"); }, &b);
    queue.submit([&] { order.push_back("b2"); }, &b);
    queue.submit([&] { order.push_back("c1"); }, &c);
    ASSERT_EQ(executor->posted.size(), 1u);  // one runner for the one slot
    executor->run_all();
    // Each key in turn, each key's tasks in their order.
    EXPECT_EQ(order, (std::vector<std::string>{"a1", "b1", "c1", "a2", "b2", "a3", "a4", "a5"}));
    // Tasks without a key share one turn.
    order.clear();
    queue.submit([&] { order.push_back("x1"); });
    queue.submit([&] { order.push_back("x2"); });
    queue.submit([&] { order.push_back("a6"); }, &a);
    executor->run_all();
    EXPECT_EQ(order, (std::vector<std::string>{"x1", "a6", "x2"}));
    queue.shutdown();
    // After shutdown a task runs on the submitting thread: never dropped.
    queue.submit([&] { order.push_back("late"); }, &a);
    EXPECT_EQ(order.back(), "late");
  }
}

}  // namespace
}  // namespace softshell::service::internal
