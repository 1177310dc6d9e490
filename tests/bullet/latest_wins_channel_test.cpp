#include "softshell/bullet/latest_wins_channel.h"

#include <thread>

#include <gtest/gtest.h>

#include "softshell/embedded_session.h"
#include "test_meshes.h"
#include "test_sessions.h"

namespace softshell::bullet {
namespace {

using namespace std::chrono_literals;
using Clock = LatestWinsChannel::Clock;

// A request told apart by its single force's index.
DeformationRequest numbered(int32_t n) {
  DeformationRequest r;
  r.forces.push_back({n, Vec3::UnitZ()});
  return r;
}

TEST(LatestWinsChannel, OneInFlightAndTheNewestWaiting) {
  auto session = std::make_shared<test::ManualSession>(test::make_grid(2, 2));
  LatestWinsChannel channel(session, GeomId{}, 0.0);
  const auto t0 = Clock::now();

  channel.submit(numbered(1), t0);  // sent at once
  EXPECT_TRUE(channel.in_flight());
  EXPECT_FALSE(channel.has_pending());
  for (int32_t n = 2; n <= 100; ++n) channel.submit(numbered(n), t0);  // each replaces the last
  EXPECT_EQ(channel.depth(), 2u);
  EXPECT_EQ(channel.stats().replaced, 98u);
  EXPECT_EQ(channel.pending()->forces[0].index, 100);
  EXPECT_EQ(session->requests().size(), 1u);  // nothing else went out

  EXPECT_FALSE(channel.poll(t0));  // not answered yet: nothing, and 100 keeps waiting
  EXPECT_EQ(session->requests().size(), 1u);

  session->answer();
  auto answer = channel.poll(t0);
  ASSERT_TRUE(answer);
  ASSERT_TRUE(answer->result.ok());
  EXPECT_EQ(answer->result->res_id, 1u);
  EXPECT_EQ(answer->request.forces[0].index, 1);  // the answer comes with its request
  // The newest went out right after.
  ASSERT_EQ(session->requests().size(), 2u);
  EXPECT_EQ(session->requests()[1].forces[0].index, 100);
  EXPECT_EQ(channel.last_sent()->forces[0].index, 100);
  EXPECT_FALSE(channel.has_pending());

  session->fail_next(Error{ErrorCode::kUnprocessable, "undetermined"});
  answer = channel.poll(t0);
  ASSERT_TRUE(answer);
  EXPECT_EQ(answer->result.error().code, ErrorCode::kUnprocessable);
  EXPECT_EQ(channel.depth(), 0u);
  EXPECT_EQ(channel.stats().sent, 2u);
  EXPECT_EQ(channel.stats().completed, 1u);
  EXPECT_EQ(channel.stats().failed, 1u);
  EXPECT_EQ(channel.stats().submitted, 100u);
  EXPECT_EQ(channel.stats().max_depth, 2u);
}

TEST(LatestWinsChannel, RateLimit) {
  auto session = std::make_shared<test::ManualSession>(test::make_grid(2, 2));
  LatestWinsChannel channel(session, GeomId{}, 10.0);  // one request per 100 ms
  const auto t0 = Clock::now();
  channel.submit(numbered(1), t0);
  session->answer();
  ASSERT_TRUE(channel.poll(t0 + 10ms));
  channel.submit(numbered(2), t0 + 20ms);  // answered quickly, but the rate holds it back
  EXPECT_FALSE(channel.in_flight());
  EXPECT_TRUE(channel.has_pending());
  EXPECT_FALSE(channel.poll(t0 + 99ms));
  EXPECT_FALSE(channel.in_flight());
  channel.submit(numbered(3), t0 + 99ms);
  EXPECT_FALSE(channel.poll(t0 + 100ms));
  EXPECT_TRUE(channel.in_flight());
  EXPECT_EQ(session->requests().back().forces[0].index, 3);
  EXPECT_EQ(channel.next_send_time(), t0 + 200ms);
}

TEST(LatestWinsChannel, RejectsBadArguments) {
  auto session = std::make_shared<test::ManualSession>(test::make_grid(2, 2));
  EXPECT_THROW(LatestWinsChannel(nullptr, GeomId{}, 0.0), Exception);
  EXPECT_THROW(LatestWinsChannel(session, GeomId{}, -1.0), Exception);
  EXPECT_THROW(LatestWinsChannel(session, GeomId{}, std::nan("")), Exception);
  EXPECT_THROW(LatestWinsChannel(session, GeomId{}, HoldTarget{"h", 0ms}), Exception);
  EXPECT_THROW(LatestWinsChannel(session, GeomId{}, HoldTarget{"h", 601s}), Exception);
  LatestWinsChannel requests(session, GeomId{});
  EXPECT_EQ(requests.release().error().code, ErrorCode::kInvalidArgument);
}

// As a hold: each request a new version, the lease renewed from poll() (a 300 ms lease outlives
// a second of polling), and released by release() or the destructor.
TEST(LatestWinsChannel, AsAHoldRenewsItsLeaseAndLetsGo) {
  auto session = std::make_shared<EmbeddedSession>();
  const GeomId id = session->upload(test::make_grid(4, 4), Material{2.0e9, 0.35, 0.005, 1200.0}).value().id;
  DeformationRequest pinned;
  for (int j = 0; j <= 1; ++j) {  // two rows clamp the edge
    for (int i = 0; i <= 4; ++i) pinned.vertex_constraints.push_back({test::grid_index(4, i, j), kAxisAll, Vec3::Zero()});
  }
  auto channel = std::make_unique<LatestWinsChannel>(session, id, HoldTarget{"pins", 300ms});
  EXPECT_EQ(channel->release().error().code, ErrorCode::kNotFound);  // never put
  channel->submit(pinned);
  ASSERT_TRUE(channel->wait(10s));
  auto answer = channel->poll();
  ASSERT_TRUE(answer && answer->result.ok()) << (answer ? answer->result.error().message : "no answer");
  ASSERT_TRUE(answer->holds);
  EXPECT_EQ(*answer->holds, (HoldVersions{{"pins", 1}}));
  const auto until = Clock::now() + 1s;
  while (Clock::now() < until) {
    EXPECT_FALSE(channel->poll());  // renewals bring no new answers
    std::this_thread::sleep_for(5ms);
  }
  EXPECT_GE(channel->stats().renewals, 3u);
  EXPECT_EQ(channel->stats().sent, 1u);
  const HoldDetail held = session->hold(id, "pins").value();
  EXPECT_EQ(held.info.version, 1u);  // renewals are no new versions
  // A refused change: the hold keeps its contents, and the renewals keep those alive (not the
  // refused ones, which would lapse the hold after its 300 ms).
  DeformationRequest bad = pinned;
  bad.forces.push_back({9999, Vec3::UnitZ()});
  channel->submit(bad);
  // A renewal may still be in flight: its answer is swallowed, and the change goes out after it.
  answer.reset();
  for (int tries = 0; tries < 3 && !answer; ++tries) {
    ASSERT_TRUE(channel->wait(10s));
    answer = channel->poll();
  }
  ASSERT_TRUE(answer && !answer->result.ok());
  const uint64_t renewals = channel->stats().renewals;
  const auto later = Clock::now() + 700ms;
  while (Clock::now() < later) {
    (void)channel->poll();
    std::this_thread::sleep_for(5ms);
  }
  EXPECT_GT(channel->stats().renewals, renewals);
  EXPECT_EQ(session->hold(id, "pins").value().info.version, 1u);
  // A change is the next version; destroying the channel releases the hold.
  DeformationRequest pushed = pinned;
  pushed.forces.push_back({test::grid_index(4, 2, 4), Vec3(0.0, 0.0, -1.0)});
  channel->submit(pushed);
  ASSERT_TRUE(channel->wait(10s));
  answer = channel->poll();
  ASSERT_TRUE(answer && answer->result.ok());
  EXPECT_EQ(*answer->holds, (HoldVersions{{"pins", 2}}));
  channel.reset();
  EXPECT_EQ(session->hold(id, "pins").error().code, ErrorCode::kNotFound);
}

}  // namespace
}  // namespace softshell::bullet
