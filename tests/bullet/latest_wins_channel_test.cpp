#include "softshell/bullet/latest_wins_channel.h"

#include <gtest/gtest.h>

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
}

}  // namespace
}  // namespace softshell::bullet
