// softshell's connection loop over cpp-httplib (server/http/src/listener.cpp): pipelined requests
// on one connection, idle keep-alive connections and stop, hundreds of plain connections at
// once, and the limits on request heads (size, deadline) and on connections per address, which
// keep slow and endless senders from starving everyone else.
#include <gtest/gtest.h>

#include <arpa/inet.h>

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


// A connection from another loopback address (127.0.0.2): the attacker in the tests below, apart
// from the normal clients on 127.0.0.1.
int connect_from(const char* source, int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return -1;
  sockaddr_in local{};
  local.sin_family = AF_INET;
  ::inet_pton(AF_INET, source, &local.sin_addr);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&local), sizeof local) != 0 ||
      ::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

int status_of(const std::string& answer) {
  return answer.rfind("HTTP/1.1 ", 0) == 0 ? std::atoi(answer.c_str() + 9) : 0;
}

TEST(HttpHeadLimitsTest, EndlessHeadersGet431AndTheConnectionCloses) {
  http::ServerOptions o = test_server_options();
  o.max_head_bytes = 16 * 1024;
  TestServer server(test_service_options(), o);
  const int fd = connect_loopback(server.port());
  ASSERT_GE(fd, 0);
  std::string head = "GET /health HTTP/1.1\r\nHost: x\r\n";
  const std::string line = "X-Filler: " + std::string(1000, 'a') + "\r\n";
  // 1 MiB of header lines: the server stops reading at 16 KiB, answers, and closes, so the
  // writes fail or the answer comes first.
  size_t sent = ::send(fd, head.data(), head.size(), MSG_NOSIGNAL);
  for (int i = 0; i < 1000; ++i) {
    const ssize_t n = ::send(fd, line.data(), line.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n <= 0) break;
    sent += static_cast<size_t>(n);
  }
  const std::string answer = read_responses(fd, 1, milliseconds(10000));
  ::close(fd);
  EXPECT_EQ(status_of(answer), 431) << answer.substr(0, 300);
  EXPECT_NE(answer.find("16 KiB"), std::string::npos) << answer.substr(0, 300);
  EXPECT_NE(answer.find("Connection: close"), std::string::npos);
  // A head within the limit is served as before.
  auto c = server.client();
  httplib::Headers big{{"X-Filler", std::string(8000, 'b')}};
  auto ok = c->Get("/health", big);
  ASSERT_TRUE(ok);
  EXPECT_EQ(ok->status, 200);
}

TEST(HttpHeadLimitsTest, AHeadTrickledSlowerThanItsDeadlineGets408) {
  http::ServerOptions o = test_server_options();
  o.head_timeout = milliseconds(800);
  o.io_timeout = std::chrono::seconds(60);  // each byte comes well within the read timeout
  TestServer server(test_service_options(), o);
  const int fd = connect_loopback(server.port());
  ASSERT_GE(fd, 0);
  const auto start = std::chrono::steady_clock::now();
  std::string answer;
  const std::string head = "GET /health HTTP/1.1\r\nHost: x\r\nX-Slow: ";
  ::send(fd, head.data(), head.size(), MSG_NOSIGNAL);
  for (int i = 0; i < 100 && answer.empty(); ++i) {  // one byte every 100 ms, never the end
    if (::send(fd, "a", 1, MSG_NOSIGNAL) <= 0) break;
    answer = read_responses(fd, 1, milliseconds(100));
  }
  if (answer.empty()) answer = read_responses(fd, 1, milliseconds(5000));
  ::close(fd);
  EXPECT_EQ(status_of(answer), 408) << answer.substr(0, 300);
  EXPECT_LT(seconds_since(start), 8.0);  // the deadline, not the 60 s read timeout
}

// Slowloris: one address opens many connections that trickle their heads. With a per-address
// limit and the head deadline, other clients are still served, and the attacker's surplus
// connections are refused at once.
TEST(HttpHeadLimitsTest, SlowHeadSendersFromOneAddressDoNotStarveOthers) {
  http::ServerOptions o = test_server_options();
  o.max_connections = 16;
  o.reserved_connections = 4;
  o.max_connections_per_address = 8;
  o.head_timeout = milliseconds(2000);
  TestServer server(test_service_options(), o);
  std::vector<int> slow;
  for (int i = 0; i < 100; ++i) {
    const int fd = connect_from("127.0.0.2", server.port());
    ASSERT_GE(fd, 0);
    const std::string start = "GET /health HTTP/1.1\r\nHost: x\r\n";  // and never the blank line
    ::send(fd, start.data(), start.size(), MSG_NOSIGNAL);
    slow.push_back(fd);
  }
  std::atomic<bool> attacking{true};
  std::thread trickle([&] {
    while (attacking.load()) {
      for (int fd : slow) ::send(fd, "X", 1, MSG_NOSIGNAL | MSG_DONTWAIT);
      std::this_thread::sleep_for(milliseconds(200));
    }
  });
  int served = 0;
  for (int i = 0; i < 5; ++i) {
    auto c = server.client();
    c->set_connection_timeout(std::chrono::seconds(5));
    c->set_read_timeout(std::chrono::seconds(5));
    auto r = c->Get("/health");
    if (r && r->status == 200) ++served;
  }
  EXPECT_EQ(served, 5);
  // Of the attacker's 100 connections at most 8 were served at once; the rest got 503.
  int refused = 0;
  for (int fd : slow) {
    const std::string answer = read_responses(fd, 1, milliseconds(50));
    if (status_of(answer) == 503) {
      ++refused;
      EXPECT_NE(answer.find("limit"), std::string::npos);
    }
  }
  EXPECT_GE(refused, 80);
  attacking.store(false);
  trickle.join();
  for (int fd : slow) ::close(fd);
}

}  // namespace
}  // namespace softshell
