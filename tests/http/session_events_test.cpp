// Event subscriptions through both sessions: the newest result at once then each new one, latest
// wins for a slow consumer, destruction while streaming, and (remote) the SSE client's resume
// with Last-Event-ID after the server dropped the stream, against the real server and a scripted
// one that checks the exact frames and headers.
#include <gtest/gtest.h>

#include <atomic>
#include <thread>

#include "session_test_support.h"

namespace softshell {
namespace {

using namespace test;
using Clock = std::chrono::steady_clock;

class SessionEventsTest : public ::testing::TestWithParam<SessionKind> {
 protected:
  TestServer server;
  std::unique_ptr<Session> session = make_session(GetParam(), server);
  GeomId id = upload_ready(*session, server);
};

// Takes results until one with `res_id` arrives (or 20 s pass); the ids taken, in order.
std::vector<uint32_t> take_until(EventSubscription& sub, uint32_t res_id) {
  std::vector<uint32_t> ids;
  const auto deadline = Clock::now() + std::chrono::seconds(20);
  while (Clock::now() < deadline && (ids.empty() || ids.back() < res_id)) {
    auto next = sub.next(std::chrono::milliseconds(200));
    if (!next) {
      ADD_FAILURE() << next.error().message;
      break;
    }
    if (*next) ids.push_back((*next)->result.res_id);
  }
  return ids;
}

TEST_P(SessionEventsTest, NewestAtOnceThenEachNewOne) {
  ASSERT_TRUE(session->deform(id, pinned_push(1)));
  ASSERT_TRUE(session->deform(id, pinned_push(2)));
  auto sub = session->subscribe(id);
  ASSERT_TRUE(sub) << sub.error().message;
  auto first = (*sub)->next(std::chrono::seconds(20));
  ASSERT_TRUE(first) << first.error().message;
  ASSERT_TRUE(*first);
  EXPECT_EQ((*first)->result.res_id, 2u);
  EXPECT_FALSE((*first)->holds);  // a result of POST .../results
  EXPECT_EQ((*sub)->last_id(), 2u);
  EXPECT_EQ((*sub)->state(), FeedState::kLive);
  EXPECT_FALSE((*sub)->poll());

  auto held = session->put_hold(id, "pins", pins());
  ASSERT_TRUE(held) << held.error().message;
  auto next = (*sub)->next(std::chrono::seconds(20));
  ASSERT_TRUE(next && *next);
  EXPECT_EQ((*next)->result.res_id, 3u);
  ASSERT_TRUE((*next)->holds);
  EXPECT_EQ(*(*next)->holds, (HoldVersions{{"pins", 1}}));
  ASSERT_EQ((*next)->result.positions.size(), held->result.positions.size());
  for (size_t i = 0; i < held->result.positions.size(); ++i) {
    EXPECT_EQ((*next)->result.positions[i], held->result.positions[i]);  // JSON on both sides: exact
  }

  // A subscription after the newest id gets nothing at once, then the next one.
  auto later = session->subscribe(id, 3);
  ASSERT_TRUE(later) << later.error().message;
  EXPECT_FALSE((*later)->next(std::chrono::milliseconds(300)).value());
  ASSERT_TRUE(session->deform(id, pinned_push(3)));
  EXPECT_EQ(take_until(**later, 4), (std::vector<uint32_t>{4}));
  EXPECT_EQ(take_until(**sub, 4), (std::vector<uint32_t>{4}));

  EXPECT_EQ(session->subscribe(GeomId{}).error().code, ErrorCode::kNotFound);
}

TEST_P(SessionEventsTest, ASlowConsumerGetsTheNewest) {
  auto sub = session->subscribe(id);
  ASSERT_TRUE(sub) << sub.error().message;
  for (int k = 1; k <= 6; ++k) ASSERT_TRUE(session->deform(id, pinned_push(k)));
  const auto ids = take_until(**sub, 6);
  ASSERT_FALSE(ids.empty());
  EXPECT_EQ(ids.back(), 6u);
  EXPECT_TRUE(std::is_sorted(ids.begin(), ids.end()));
  EXPECT_EQ(std::adjacent_find(ids.begin(), ids.end()), ids.end());  // no repeats
  EXPECT_FALSE((*sub)->poll());
}

TEST_P(SessionEventsTest, DestroyingASubscriptionReturnsPromptly) {
  ASSERT_TRUE(session->deform(id, pinned_push(1)));
  // Idle: the stream is waiting for the next result (a remote one is blocked in a read).
  {
    auto sub = session->subscribe(id);
    ASSERT_TRUE(sub) << sub.error().message;
    ASSERT_TRUE((*sub)->next(std::chrono::seconds(20)).value());
    const auto t0 = Clock::now();
    sub->reset();
    EXPECT_LT(seconds_since(t0), 10.0);  // a hang, not a speed check: the idle timeout is 45 s
  }
  // While results stream in.
  std::atomic<bool> stop{false};
  std::thread producer([&] {
    for (int k = 2; !stop.load(); ++k) (void)session->deform(id, pinned_push(k % 7 + 1));
  });
  for (int round = 0; round < 5; ++round) {
    auto sub = session->subscribe(id);
    ASSERT_TRUE(sub) << sub.error().message;
    (void)(*sub)->next(std::chrono::seconds(5));
    const auto t0 = Clock::now();
    sub->reset();
    EXPECT_LT(seconds_since(t0), 10.0);
  }
  stop.store(true);
  producer.join();
}

INSTANTIATE_TEST_SUITE_P(Sessions, SessionEventsTest,
                         ::testing::Values(SessionKind::kEmbedded, SessionKind::kRemoteBinary, SessionKind::kRemoteJson),
                         [](const auto& p) { return std::string(name_of(p.param)); });

// The server stops (its streams end) and comes back on the same port: the subscription
// reconnects by itself and delivers the newest result stored meanwhile, then the next ones.
TEST(RemoteEventsTest, ResumesAfterTheServerDroppedTheStream) {
  auto service = std::make_shared<service::Service>(test_service_options());
  auto http = std::make_unique<http::HttpServer>(service, test_server_options());
  const int port = http->start("127.0.0.1", 0).value();
  RemoteSession remote("http://127.0.0.1:" + std::to_string(port), remote_options(SessionKind::kRemoteJson));
  const GeomId id = remote.upload(exact_grid(), exact_material()).value().id;
  ASSERT_TRUE(remote.deform(id, pinned_push(1)));
  auto sub = remote.subscribe(id);
  ASSERT_TRUE(sub) << sub.error().message;
  EXPECT_EQ(take_until(**sub, 1), (std::vector<uint32_t>{1}));

  http->stop();
  http.reset();
  for (int i = 0; i < 1000 && (*sub)->state() == FeedState::kLive; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_EQ((*sub)->state(), FeedState::kConnecting);
  ASSERT_TRUE((*sub)->error());
  EXPECT_EQ((*sub)->error()->code, ErrorCode::kUnavailable);
  // Stored while no server listens.
  ASSERT_TRUE(service->deform(id, pinned_push(2)).get());
  ASSERT_TRUE(service->deform(id, pinned_push(3)).get());

  http = std::make_unique<http::HttpServer>(service, test_server_options());
  auto again = http->start("127.0.0.1", port);
  ASSERT_TRUE(again) << again.error().message;
  auto resumed = (*sub)->next(std::chrono::seconds(20));
  ASSERT_TRUE(resumed && *resumed);
  EXPECT_EQ((*resumed)->result.res_id, 3u);  // the newest, at once
  EXPECT_EQ((*sub)->state(), FeedState::kLive);
  ASSERT_TRUE(service->deform(id, pinned_push(4)).get());
  EXPECT_EQ(take_until(**sub, 4), (std::vector<uint32_t>{4}));
  sub->reset();
  http->stop();
}

// A scripted event server: the first stream sends one event (CRLF lines, a comment) and ends; the
// second must carry `Last-Event-ID` and gets an event whose data spans two lines, an event of
// another type, a keep-alive, then stays open until the test ends.
TEST(RemoteEventsTest, ParsesTheFramesAndSendsLastEventIdOnReconnect) {
  const GeomId id = GeomId::from_hex(std::string(32, 'a')).value();
  httplib::Server fake;
  std::atomic<int> connections{0};
  std::atomic<bool> closing{false};
  std::mutex mu;
  std::vector<std::string> last_event_ids;
  fake.Get("/geometries/" + id.hex() + "/events", [&](const httplib::Request& req, httplib::Response& res) {
    const int n = ++connections;
    {
      std::lock_guard lock(mu);
      last_event_ids.push_back(req.get_header_value("Last-Event-ID"));
    }
    res.set_chunked_content_provider("text/event-stream", [&, n, sent = false](size_t, httplib::DataSink& sink) mutable {
      if (!sent) {
        sent = true;
        const std::string frames =
            n == 1 ? ": hello\r\nid: 7\r\nevent: result\r\ndata: {\"res_id\": 7, \"positions\": [[1, 2, 3]]}\r\n\r\n"
                   : "event: ping\ndata: {}\n\nid: 8\nevent: result\ndata: {\"res_id\": 8,\ndata:  \"positions\": "
                     "[[4, 5, 6]], \"holds\": {\"a\": 2}}\n\n: keep-alive\n\n";
        sink.write(frames.data(), frames.size());
        if (n == 1) sink.done();
        return true;
      }
      if (closing.load()) {
        sink.done();
        return true;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      return true;
    });
  });
  const int port = fake.bind_to_any_port("127.0.0.1");
  ASSERT_GT(port, 0);
  std::thread serving([&] { fake.listen_after_bind(); });

  RemoteSession remote("http://127.0.0.1:" + std::to_string(port), remote_options(SessionKind::kRemoteJson));
  auto sub = remote.subscribe(id);
  ASSERT_TRUE(sub) << sub.error().message;
  auto first = (*sub)->next(std::chrono::seconds(20));
  ASSERT_TRUE(first && *first);
  EXPECT_EQ((*first)->result.res_id, 7u);
  EXPECT_EQ((*first)->result.positions, (std::vector<Vec3>{Vec3(1, 2, 3)}));
  auto second = (*sub)->next(std::chrono::seconds(20));
  ASSERT_TRUE(second && *second) << ((*sub)->error() ? (*sub)->error()->message : "");
  EXPECT_EQ((*second)->result.res_id, 8u);
  EXPECT_EQ((*second)->result.positions, (std::vector<Vec3>{Vec3(4, 5, 6)}));
  EXPECT_EQ((*second)->holds, (HoldVersions{{"a", 2}}));
  EXPECT_EQ(connections.load(), 2);
  {
    std::lock_guard lock(mu);
    EXPECT_EQ(last_event_ids, (std::vector<std::string>{"", "7"}));
  }
  sub->reset();  // closes the second stream
  closing.store(true);
  fake.stop();
  serving.join();
}

TEST(RemoteEventsTest, NoServerIsAnErrorAtOnce) {
  RemoteSessionOptions o = remote_options(SessionKind::kRemoteJson);
  o.connect_timeout = std::chrono::seconds(2);
  int port = 0;
  {
    TestServer gone;  // a port that was just free
    port = gone.port();
  }
  RemoteSession remote("http://127.0.0.1:" + std::to_string(port), o);
  auto sub = remote.subscribe(GeomId{});
  ASSERT_FALSE(sub);
  EXPECT_EQ(sub.error().code, ErrorCode::kUnavailable);
  EXPECT_NE(sub.error().message.find("connection refused"), std::string::npos) << sub.error().message;
}

}  // namespace
}  // namespace softshell
