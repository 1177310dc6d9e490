// Concurrency over real sockets: many deforming clients and long-polling clients at once,
// long polls that cannot starve solves, the long-poll limit, and shutdown.
#include <gtest/gtest.h>

#include <atomic>
#include <set>
#include <thread>

#include "http_test_support.h"
#include "softshell/remote_session.h"

namespace softshell {
namespace {

using namespace test;

GeomId upload_ready(TestServer& server) {
  auto up = server.service().upload(exact_grid(), exact_material());
  EXPECT_TRUE(up);
  (void)server.service().wait_until_precomputed(up->id, std::chrono::seconds(30));
  return up->id;
}

TEST(HttpConcurrencyTest, EightDeformingClientsAndFiftyLongPollers) {
  TestServer server;
  const GeomId id = upload_ready(server);
  const std::string base = "/geometries/" + id.hex();
  constexpr int kClients = 8, kEach = 10, kWaiters = 50, kTotal = kClients * kEach;

  std::atomic<int> failures{0};
  std::vector<uint32_t> final_seen(kWaiters, 0);
  std::vector<int> wakeups(kWaiters, 0);
  std::vector<std::thread> threads;
  for (int w = 0; w < kWaiters; ++w) {
    threads.emplace_back([&, w] {
      auto c = server.client(60);
      uint32_t have = 0;
      while (have < static_cast<uint32_t>(kTotal)) {
        // Alternate formats: half the waiters ask for binary.
        Reply r = get(*c, base + "/latest_result?have=" + std::to_string(have) + "&wait=30", w % 2 ? kBin : kJson);
        if (r.status != 200) {
          failures.fetch_add(1);
          ADD_FAILURE() << "waiter " << w << " got " << r.status << " " << r.body;
          return;
        }
        auto result = w % 2 ? wire::decode_result_binary(r.body, 25) : wire::decode_result_json(r.body, 25);
        if (!result || result->res_id <= have) {
          failures.fetch_add(1);
          return;
        }
        have = result->res_id;
        ++wakeups[w];
      }
      final_seen[w] = have;
    });
  }
  // Deforming clients: half binary through RemoteSession, half JSON by hand.
  std::vector<std::vector<uint32_t>> ids(kClients);
  for (int k = 0; k < kClients; ++k) {
    threads.emplace_back([&, k] {
      RemoteSessionOptions options;
      options.format = k % 2 ? wire::Format::kBinary : wire::Format::kJson;
      RemoteSession session(server.url(), options);
      for (int i = 0; i < kEach; ++i) {
        auto r = session.deform(id, pinned_push(1 + (k + i) % 5));
        if (!r) {
          failures.fetch_add(1);
          ADD_FAILURE() << r.error().message;
          continue;
        }
        ids[k].push_back(r->res_id);
      }
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(failures.load(), 0);
  std::set<uint32_t> all;
  for (const auto& v : ids) {
    EXPECT_TRUE(std::is_sorted(v.begin(), v.end()));
    all.insert(v.begin(), v.end());
  }
  ASSERT_EQ(all.size(), static_cast<size_t>(kTotal)) << "ids are not unique";
  EXPECT_EQ(*all.begin(), 1u);
  EXPECT_EQ(*all.rbegin(), static_cast<uint32_t>(kTotal)) << "ids are not contiguous";
  for (int w = 0; w < kWaiters; ++w) {
    EXPECT_EQ(final_seen[w], static_cast<uint32_t>(kTotal)) << "waiter " << w;
    EXPECT_GE(wakeups[w], 1);
  }
  auto c = server.client();
  EXPECT_EQ(wire::decode_result_ids_json(get(*c, base + "/results").body)->size(), static_cast<size_t>(kTotal));
  for (const auto& e : server.http().endpoint_stats()) EXPECT_EQ(e.server_errors, 0u) << e.endpoint;
}

TEST(HttpConcurrencyTest, HundredsOfLongPollsDoNotStarveSolves) {
  service::ServiceOptions so = test_service_options();
  so.solve_threads = 1;  // a single compute worker
  http::ServerOptions ho = test_server_options();
  ho.max_connections = 300;
  ho.reserved_connections = 16;
  TestServer server(so, ho);
  const GeomId id = upload_ready(server);
  const std::string base = "/geometries/" + id.hex();
  constexpr int kWaiters = 200;

  std::vector<int> status(kWaiters, 0);
  std::vector<std::thread> waiters;
  for (int w = 0; w < kWaiters; ++w) {
    waiters.emplace_back([&, w] {
      auto c = server.client(60);
      status[w] = get(*c, base + "/latest_result?have=0&wait=30").status;
    });
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (server.http().waiting_long_polls() < kWaiters && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(Ms(2));
  }
  ASSERT_EQ(server.http().waiting_long_polls(), kWaiters);

  // With every waiter parked, other requests are served at once: health, an upload, a solve.
  auto c = server.client();
  auto start = std::chrono::steady_clock::now();
  EXPECT_EQ(get(*c, "/health").status, 200);
  EXPECT_EQ(post(*c, "/geometries", wire::encode_geometry_binary(exact_grid(2), exact_material()).value(), kBin).status,
            201);
  Reply solved = post(*c, base + "/results", wire::encode_request_binary(pinned_push(1)).value(), kBin);
  const double solve_latency = seconds_since(start);
  EXPECT_EQ(solved.status, 200);
  EXPECT_LT(solve_latency, 5.0) << "the solve waited behind the long polls";
  RecordProperty("solve_latency_with_200_waiters_us", static_cast<int>(solve_latency * 1e6));
  for (auto& t : waiters) t.join();
  for (int w = 0; w < kWaiters; ++w) EXPECT_EQ(status[w], 200) << "waiter " << w;
}

TEST(HttpConcurrencyTest, IdleConnectionThreadsExitAfterABurst) {
  http::ServerOptions ho = test_server_options();
  ho.idle_thread_exit = Ms(200);
  TestServer server(test_service_options(), ho);
  const GeomId id = upload_ready(server);
  const std::string base = "/geometries/" + id.hex();
  constexpr int kBurst = 40;
  std::vector<std::thread> waiters;
  for (int w = 0; w < kBurst; ++w) {
    waiters.emplace_back([&] {
      auto c = server.client(60);
      c->set_keep_alive(false);
      EXPECT_EQ(get(*c, base + "/latest_result?wait=30").status, 200);
    });
  }
  while (server.http().waiting_long_polls() < kBurst) std::this_thread::sleep_for(Ms(1));
  EXPECT_GE(server.http().connection_threads(), kBurst);
  EXPECT_TRUE(server.service().deform(id, pinned_push(1)).get());
  for (auto& t : waiters) t.join();
  // Idle threads leave; a few are kept. The server still serves (and reaps on the next accept).
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (server.http().connection_threads() > 8 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(Ms(20));
  }
  EXPECT_LE(server.http().connection_threads(), 8);
  EXPECT_EQ(get(*server.client(), "/health").status, 200);
  EXPECT_NE(get(*server.client(), "/metrics").body.find("softshell_http_connection_threads"), std::string::npos);
}

TEST(HttpConcurrencyTest, LongPollsBeyondTheLimitGet503) {
  http::ServerOptions ho = test_server_options();
  ho.max_connections = 16;
  ho.reserved_connections = 12;  // at most 4 long polls
  TestServer server(test_service_options(), ho);
  const GeomId id = upload_ready(server);
  const std::string base = "/geometries/" + id.hex();
  std::vector<std::thread> waiters;
  std::vector<int> status(4, 0);
  for (int w = 0; w < 4; ++w) {
    waiters.emplace_back([&, w] { status[w] = get(*server.client(60), base + "/latest_result?wait=30").status; });
  }
  while (server.http().waiting_long_polls() < 4) std::this_thread::sleep_for(Ms(1));
  auto c = server.client();
  auto r = c->Get(base + "/latest_result?wait=30");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 503);
  EXPECT_EQ(r->get_header_value("Retry-After"), "1");
  EXPECT_NE(r->body.find("unavailable"), std::string::npos);
  // wait=0 is no long poll: still answered.
  EXPECT_EQ(get(*c, base + "/latest_result?wait=0").status, 204);
  EXPECT_EQ(post(*c, base + "/results", wire::encode_request_json(pinned_push(1)), kJson).status, 200);
  for (auto& t : waiters) t.join();
  for (int s : status) EXPECT_EQ(s, 200);
}

TEST(HttpConcurrencyTest, StopReleasesWaitersPromptly) {
  auto server = std::make_unique<TestServer>();
  const GeomId id = upload_ready(*server);
  const std::string base = "/geometries/" + id.hex();
  constexpr int kWaiters = 20;
  std::vector<int> status(kWaiters, 0);
  std::vector<std::thread> waiters;
  for (int w = 0; w < kWaiters; ++w) {
    waiters.emplace_back([&, w] {
      auto c = server->client(60);
      c->set_keep_alive(false);
      auto r = c->Get(base + "/latest_result?wait=60");
      status[w] = r ? r->status : -1;
    });
  }
  while (server->http().waiting_long_polls() < kWaiters) std::this_thread::sleep_for(Ms(1));
  const auto start = std::chrono::steady_clock::now();
  server->http().stop();
  for (auto& t : waiters) t.join();
  EXPECT_LT(seconds_since(start), 5.0);
  for (int w = 0; w < kWaiters; ++w) EXPECT_EQ(status[w], 503) << "waiter " << w;
  EXPECT_FALSE(server->http().running());
  // The service itself keeps running (an embedded app may close its listener only).
  EXPECT_TRUE(server->service().deform(id, pinned_push(1)).get());
  server.reset();
}

TEST(HttpConcurrencyTest, RemoteSessionErrorsAreValues) {
  // Nothing listens on this port: every call fails with kUnavailable, nothing throws.
  int port = 0;
  {
    TestServer probe;
    port = probe.port();
  }
  RemoteSessionOptions options;
  options.connect_timeout = Ms(500);
  RemoteSession session("http://127.0.0.1:" + std::to_string(port), options);
  EXPECT_EQ(session.health().error().code, ErrorCode::kUnavailable);
  // The message says what to check, not httplib's name for the failure ("Connection").
  EXPECT_EQ(session.health().error().message,
            "connection refused: is softshell-server running at http://127.0.0.1:" + std::to_string(port) + "?");
  EXPECT_EQ(session.upload(exact_grid(), exact_material()).error().code, ErrorCode::kUnavailable);
  auto async = session.deform_async(GeomId{}, pinned_push(1));
  EXPECT_EQ(async.get().error().code, ErrorCode::kUnavailable);
  EXPECT_FALSE(RemoteSession::connect("http://127.0.0.1:" + std::to_string(port), options));
  RemoteSession nonsense("::not a url::");
  EXPECT_FALSE(nonsense.health());
}

}  // namespace
}  // namespace softshell
