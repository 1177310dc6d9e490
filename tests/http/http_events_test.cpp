// GET /geometries/{id}/events (Server-Sent Events, PROTOCOL.md version 2) over real sockets: the
// stream's layout, resume with have and Last-Event-ID, keep-alive comments, errors, HTTP/1.0,
// a slow follower (latest wins), hang-ups, shutdown with streams and holds open, and more than
// 1,024 connections open at once.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <memory>
#include <thread>

#include "http_test_support.h"
#include "sse_client.h"

namespace softshell {
namespace {

using namespace test;
using std::chrono::milliseconds;

struct Geo {
  GeomId id;
  std::string base;
};

Geo upload_ready(TestServer& server, const ControlMesh& mesh = exact_grid()) {
  auto up = server.service().upload(mesh, exact_material());
  EXPECT_TRUE(up) << up.error().message;
  (void)server.service().wait_until_precomputed(up->id, std::chrono::seconds(30));
  return {up->id, "/geometries/" + up->id.hex()};
}

uint32_t deform(TestServer& server, const Geo& g, int k = 1, int n = 4) {
  auto r = server.service().deform(g.id, pinned_push(k, n)).get();
  EXPECT_TRUE(r) << r.error().message;
  return r ? (*r)->res_id : 0;
}

// The event of a stored result must carry exactly its JSON layout.
void expect_event_of(TestServer& server, const Geo& g, const SseEvent& e, uint32_t res_id) {
  EXPECT_FALSE(e.comment);
  EXPECT_EQ(e.event, "result");
  EXPECT_EQ(e.id, std::to_string(res_id));
  auto c = server.client();
  Reply stored = get(*c, g.base + "/results/" + std::to_string(res_id));
  EXPECT_EQ(e.data, stored.body);  // one line of the JSON result layout, byte for byte
  EXPECT_EQ(e.data.find('\n'), std::string::npos);
}

TEST(HttpEventsTest, NewestAtOnceThenEachNewResult) {
  TestServer server;
  const Geo g = upload_ready(server);
  deform(server, g, 1);
  deform(server, g, 2);
  SseClient s(server.port(), g.base + "/events");
  ASSERT_TRUE(s.read_head(milliseconds(10000)));
  EXPECT_EQ(s.parser().status(), 200);
  EXPECT_EQ(s.parser().header("Content-Type"), "text/event-stream");
  EXPECT_EQ(s.parser().header("Cache-Control"), "no-cache");
  EXPECT_TRUE(s.parser().chunked());
  auto first = s.next_result(milliseconds(10000));
  ASSERT_TRUE(first);
  expect_event_of(server, g, *first, 2);  // the newest, not every one

  // Each new result, from holds and from POST .../results.
  DeformationRequest pins;
  pins.vertex_constraints = pinned_corners();
  ASSERT_TRUE(server.service().put_hold(g.id, "pins", pins));
  auto third = s.next_result(milliseconds(10000));
  ASSERT_TRUE(third);
  expect_event_of(server, g, *third, 3);
  auto parsed = wire::decode_held_result_json(third->data, 25);
  ASSERT_TRUE(parsed);
  EXPECT_EQ(*parsed->holds, (HoldVersions{{"pins", 1}}));
  deform(server, g, 3);
  auto fourth = s.next_result(milliseconds(10000));
  ASSERT_TRUE(fourth);
  expect_event_of(server, g, *fourth, 4);
  EXPECT_EQ(server.http().event_streams(), 1);
}

TEST(HttpEventsTest, NothingAtOnceWithoutResultsThenTheFirst) {
  TestServer server;
  const Geo g = upload_ready(server);
  SseClient s(server.port(), g.base + "/events");
  ASSERT_TRUE(s.read_head(milliseconds(10000)));
  EXPECT_EQ(s.parser().status(), 200);
  EXPECT_FALSE(s.next_result(milliseconds(200)));
  deform(server, g, 1);
  auto e = s.next_result(milliseconds(10000));  // (delivery lag: tests/bench/bench_events)
  ASSERT_TRUE(e);
  EXPECT_EQ(e->id, "1");
}

TEST(HttpEventsTest, ResumeWithHaveAndLastEventId) {
  http::ServerOptions o = test_server_options();
  o.event_writers = 2;
  TestServer server(test_service_options(), o);
  const Geo g = upload_ready(server);
  for (int k = 1; k <= 3; ++k) deform(server, g, k);
  {
    SseClient s(server.port(), g.base + "/events?have=3");
    ASSERT_TRUE(s.read_head(milliseconds(10000)));
    EXPECT_FALSE(s.next_result(milliseconds(200)));  // it has the newest
    deform(server, g, 4);
    auto e = s.next_result(milliseconds(10000));
    ASSERT_TRUE(e);
    EXPECT_EQ(e->id, "4");
  }
  {
    // Last-Event-ID takes precedence over have.
    SseClient s(server.port(), g.base + "/events?have=4", {"Last-Event-ID: 2"});
    auto e = s.next_result(milliseconds(10000));
    ASSERT_TRUE(e);
    expect_event_of(server, g, *e, 4);
  }
  {
    SseClient s(server.port(), g.base + "/events?have=1", {"Last-Event-ID: 4"});
    ASSERT_TRUE(s.read_head(milliseconds(10000)));
    EXPECT_FALSE(s.next_result(milliseconds(200)));
  }
}

TEST(HttpEventsTest, KeepAliveComments) {
  http::ServerOptions o = test_server_options();
  o.event_keep_alive = milliseconds(150);
  TestServer server(test_service_options(), o);
  const Geo g = upload_ready(server);
  SseClient s(server.port(), g.base + "/events");
  ASSERT_TRUE(s.read_head(milliseconds(10000)));
  int comments = 0;
  for (int i = 0; i < 2; ++i) {
    auto e = s.next(milliseconds(5000));  // the sweep runs every second
    ASSERT_TRUE(e);
    EXPECT_TRUE(e->comment);
    EXPECT_EQ(e->text, " keep-alive");
    ++comments;
  }
  EXPECT_EQ(comments, 2);
}

TEST(HttpEventsTest, ErrorsAreAnsweredBeforeTheStream) {
  TestServer server;
  const Geo g = upload_ready(server);
  auto c = server.client();
  Reply unknown = get(*c, "/geometries/" + std::string(32, '0') + "/events");
  EXPECT_EQ(unknown.status, 404);
  EXPECT_EQ(error_code(unknown), "not_found");
  EXPECT_EQ(get(*c, "/geometries/nothex/events").status, 400);
  EXPECT_EQ(get(*c, g.base + "/events?have=-1").status, 400);
  httplib::Headers bad{{"Last-Event-ID", "seventeen"}};
  auto r = c->Get((g.base + "/events").c_str(), bad);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 400);
  EXPECT_NE(r->body.find("Last-Event-ID"), std::string::npos);
  // The connection that asked is served normally afterwards.
  EXPECT_EQ(get(*c, "/health").status, 200);
  EXPECT_EQ(server.http().event_streams(), 0);
}

TEST(HttpEventsTest, ServiceShuttingDownIs503) {
  TestServer server;
  const Geo g = upload_ready(server);
  server.service().shutdown();
  auto c = server.client();
  Reply r = get(*c, g.base + "/events");
  EXPECT_EQ(r.status, 503);
  EXPECT_EQ(error_code(r), "unavailable");
}

TEST(HttpEventsTest, Http10StreamHasNoChunkedFraming) {
  TestServer server;
  const Geo g = upload_ready(server);
  deform(server, g, 1);
  SseClient s(server.port(), g.base + "/events", {}, 0, "HTTP/1.0");
  auto e = s.next_result(milliseconds(10000));
  ASSERT_TRUE(e);
  EXPECT_FALSE(s.parser().chunked());
  EXPECT_EQ(s.parser().header("Connection"), "close");
  expect_event_of(server, g, *e, 1);
}

TEST(HttpEventsTest, SlowFollowerGetsOnlyTheNewest) {
  // A follower that does not read while many large results are stored: the server keeps at most
  // one waiting frame for it (plus the kernel's socket buffers, at most a few MB on Linux), so it
  // skips results and, once it reads, ends on the newest one.
  TestServer server;
  const ControlMesh mesh = make_grid(40, 40);  // ~100 KB per JSON event
  const Geo g = upload_ready(server, mesh);
  SseClient s(server.port(), g.base + "/events", {}, /*rcvbuf=*/4096);
  ASSERT_TRUE(s.read_head(milliseconds(10000)));
  constexpr int kResults = 120;  // ~12 MB of events, more than the socket buffers hold
  uint32_t newest = 0;
  for (int k = 1; k <= kResults; ++k) newest = deform(server, g, k, 40);
  std::vector<uint32_t> ids;
  while (ids.empty() || ids.back() < newest) {
    auto e = s.next_result(milliseconds(20000));
    ASSERT_TRUE(e) << "after " << ids.size() << " events";
    ids.push_back(static_cast<uint32_t>(std::stoul(e->id)));
  }
  for (size_t i = 1; i < ids.size(); ++i) EXPECT_GT(ids[i], ids[i - 1]);
  EXPECT_EQ(ids.back(), newest);
  EXPECT_LT(ids.size(), static_cast<size_t>(kResults));
  auto c = server.client();
  const std::string metrics = get(*c, "/metrics").body;
  EXPECT_EQ(metrics.find("softshell_http_event_frames_replaced_total 0\n"), std::string::npos) << metrics;
}

TEST(HttpEventsTest, HangUpEndsTheStream) {
  TestServer server;
  const Geo g = upload_ready(server);
  {
    SseClient s(server.port(), g.base + "/events");
    ASSERT_TRUE(s.read_head(milliseconds(10000)));
    EXPECT_EQ(server.http().event_streams(), 1);
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (server.http().event_streams() != 0 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(milliseconds(5));
  }
  EXPECT_EQ(server.http().event_streams(), 0);
  EXPECT_EQ(server.service().stats().followers, 0u);
}

TEST(HttpEventsTest, ShutdownWithHoldsAndStreamsOpenEndsEveryStreamCleanly) {
  http::ServerOptions o = test_server_options();
  o.event_writers = 3;  // every writer ends its streams
  auto server = std::make_unique<TestServer>(test_service_options(), o);
  const Geo g = upload_ready(*server);
  DeformationRequest pins;
  pins.vertex_constraints = pinned_corners();
  ASSERT_TRUE(server->service().put_hold(g.id, "pins", pins, {std::chrono::seconds(600)}));
  std::vector<std::unique_ptr<SseClient>> streams;
  for (int i = 0; i < 20; ++i) {
    streams.push_back(std::make_unique<SseClient>(server->port(), g.base + "/events"));
    ASSERT_TRUE(streams.back()->next_result(milliseconds(10000)));
  }
  // A long poll waiting for a result that will not come.
  std::thread poller([&] {
    auto c = server->client();
    Reply r = get(*c, g.base + "/latest_result?have=99&wait=30");
    EXPECT_EQ(r.status, 503);
  });
  const auto start = std::chrono::steady_clock::now();
  std::this_thread::sleep_for(milliseconds(100));
  server->http().stop();
  poller.join();
  for (auto& s : streams) {
    EXPECT_TRUE(s->read_to_end(milliseconds(5000)));
    EXPECT_TRUE(s->parser().clean_end());  // the last chunk, after complete events only
  }
  EXPECT_LT(seconds_since(start), 5.0);
  server.reset();  // service with its holds and leases
}

// Raises the soft descriptor limit so that this process can hold both ends of `n` connections.
bool enough_descriptors(rlim_t n) {
  rlimit lim{};
  if (::getrlimit(RLIMIT_NOFILE, &lim) != 0) return false;
  if (lim.rlim_cur >= n) return true;
  if (lim.rlim_max != RLIM_INFINITY && lim.rlim_max < n) return false;
  lim.rlim_cur = n;
  return ::setrlimit(RLIMIT_NOFILE, &lim) == 0;
}

TEST(HttpEventsTest, MoreThan1024ConnectionsOpenAtOnce) {
  // Descriptor numbers well above 1024 on both ends (select() would corrupt memory there).
  constexpr int kStreams = 1100;
  if (!enough_descriptors(2 * kStreams + 512)) GTEST_SKIP() << "the hard descriptor limit is below " << 2 * kStreams + 512;
  http::ServerOptions o = test_server_options();
  o.event_writers = 3;  // streams dealt to three writers; each result serialized once for all
  TestServer server(test_service_options(), o);
  const Geo g = upload_ready(server);
  deform(server, g, 1);
  std::vector<std::unique_ptr<SseClient>> streams;
  for (int i = 0; i < kStreams; ++i) {
    streams.push_back(std::make_unique<SseClient>(server.port(), g.base + "/events"));
    ASSERT_TRUE(streams.back()->connected()) << "connection " << i;
  }
  EXPECT_GT(streams.back()->fd(), 1024);
  const std::string expected_1 = get(*server.client(), g.base + "/results/1").body;
  for (auto& s : streams) {
    auto e = s->next_result(milliseconds(20000));
    ASSERT_TRUE(e);
    EXPECT_EQ(e->id, "1");
    EXPECT_EQ(e->data, expected_1);
  }
  EXPECT_EQ(server.http().event_streams(), kStreams);
  // New connections (descriptors above 2,200 in this process) are served, and every stream gets
  // the next result intact.
  std::vector<std::thread> clients;
  std::atomic<int> ok{0};
  for (int i = 0; i < 16; ++i) {
    clients.emplace_back([&, i] {
      auto c = server.client();
      for (int k = 0; k < 5; ++k) {
        if (get(*c, "/health").status == 200 && get(*c, g.base + "/results").status == 200) ok.fetch_add(1);
      }
      (void)i;
    });
  }
  for (auto& t : clients) t.join();
  EXPECT_EQ(ok.load(), 16 * 5);
  const uint32_t second = deform(server, g, 2);
  const std::string expected_2 = get(*server.client(), g.base + "/results/" + std::to_string(second)).body;
  for (auto& s : streams) {
    auto e = s->next_result(milliseconds(20000));
    ASSERT_TRUE(e);
    EXPECT_EQ(e->data, expected_2);
  }
  EXPECT_EQ(get(*server.client(), "/health").status, 200);
  const std::string metrics = get(*server.client(), "/metrics").body;
  EXPECT_NE(metrics.find("softshell_http_event_frames_serialized_total 2\n"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("softshell_http_event_streams 1100\n"), std::string::npos);
}

// The event writer sends the stream's head itself: with --cors-origin an allowed Origin gets the
// CORS headers there too (a page elsewhere reads the stream), any other Origin none.
TEST(HttpEventsTest, CorsHeadersOnTheStreamForAllowedOrigins) {
  http::ServerOptions options = test_server_options();
  options.cors_origins = {"http://app.example:3000"};
  TestServer server(test_service_options(), options);
  const Geo g = upload_ready(server);
  deform(server, g, 1);
  SseClient allowed(server.port(), g.base + "/events", {"Origin: http://app.example:3000"});
  ASSERT_TRUE(allowed.read_head(milliseconds(10000)));
  EXPECT_EQ(allowed.parser().status(), 200);
  EXPECT_EQ(allowed.parser().header("Access-Control-Allow-Origin"), "http://app.example:3000");
  EXPECT_EQ(allowed.parser().header("Vary"), "Origin");
  EXPECT_TRUE(allowed.parser().chunked());
  auto first = allowed.next_result(milliseconds(10000));
  ASSERT_TRUE(first);
  expect_event_of(server, g, *first, 1);

  SseClient other(server.port(), g.base + "/events", {"Origin: http://evil.example"});
  ASSERT_TRUE(other.read_head(milliseconds(10000)));
  EXPECT_EQ(other.parser().status(), 200);
  EXPECT_EQ(other.parser().header("Access-Control-Allow-Origin"), "");
}

}  // namespace
}  // namespace softshell
