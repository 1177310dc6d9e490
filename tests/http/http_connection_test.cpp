// softshell's connection loop over cpp-httplib (server/http/src/listener.cpp): pipelined requests
// on one connection, idle keep-alive connections and stop, and hundreds of plain connections at
// once.
#include <gtest/gtest.h>

#include <thread>

#include "http_test_support.h"
#include "sse_client.h"

namespace softshell {
namespace {

using namespace test;
using std::chrono::milliseconds;

// Reads from a raw socket until `count` responses (status lines) are in or the peer closes.
std::string read_responses(int fd, int count, milliseconds timeout) {
  std::string data;
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  auto responses = [&] {
    int n = 0;
    for (size_t at = data.find("HTTP/1.1 "); at != std::string::npos; at = data.find("HTTP/1.1 ", at + 1)) ++n;
    return n;
  };
  while (responses() < count && std::chrono::steady_clock::now() < deadline) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 100) <= 0) continue;
    char buf[8192];
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) break;
    data.append(buf, static_cast<size_t>(n));
  }
  return data;
}

TEST(HttpConnectionTest, PipelinedRequestsAreAnsweredInOrder) {
  TestServer server;
  const int fd = connect_loopback(server.port());
  ASSERT_GE(fd, 0);
  // Five requests in one write: three GETs, a POST with a body, and a last GET that closes.
  const std::string requests =
      "GET /health HTTP/1.1\r\nHost: x\r\n\r\n"
      "GET /geometries HTTP/1.1\r\nHost: x\r\n\r\n"
      "GET /health HTTP/1.1\r\nHost: x\r\n\r\n"
      "POST /geometries HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: 2\r\n\r\n{}"
      "GET /nothing HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n";
  ASSERT_EQ(::send(fd, requests.data(), requests.size(), MSG_NOSIGNAL), static_cast<ssize_t>(requests.size()));
  const std::string data = read_responses(fd, 5, milliseconds(10000));
  ::close(fd);
  std::vector<int> statuses;
  for (size_t at = data.find("HTTP/1.1 "); at != std::string::npos; at = data.find("HTTP/1.1 ", at + 1)) {
    statuses.push_back(std::atoi(data.c_str() + at + 9));
  }
  EXPECT_EQ(statuses, (std::vector<int>{200, 200, 200, 400, 404})) << data;
}

TEST(HttpConnectionTest, IdleKeepAliveConnectionsDoNotDelayStop) {
  http::ServerOptions o = test_server_options();
  o.keep_alive_timeout = std::chrono::seconds(30);  // they would otherwise stay for 30 s
  TestServer server(test_service_options(), o);
  std::vector<std::unique_ptr<httplib::Client>> clients;
  for (int i = 0; i < 50; ++i) {
    clients.push_back(server.client());
    ASSERT_EQ(get(*clients.back(), "/health").status, 200);
  }
  EXPECT_EQ(server.http().busy_connections(), 50);  // each waiting for its next request
  const auto start = std::chrono::steady_clock::now();
  server.http().stop();
  EXPECT_LT(seconds_since(start), 2.0);
  EXPECT_EQ(server.http().busy_connections(), 0);
}

TEST(HttpConnectionTest, HundredsOfConnectionsAtOnce) {
  TestServer server;
  constexpr int kThreads = 8, kEach = 40;
  std::atomic<int> ok{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&] {
      std::vector<std::unique_ptr<httplib::Client>> mine;
      for (int i = 0; i < kEach; ++i) mine.push_back(server.client());  // each its own connection
      for (int round = 0; round < 2; ++round) {
        for (auto& c : mine) {
          if (get(*c, "/health").status == 200) ok.fetch_add(1);
        }
      }
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(ok.load(), kThreads * kEach * 2);
}

}  // namespace
}  // namespace softshell
