// Request body framing on real sockets (server.cpp's refuse_body, listener.cpp's lingering
// close): chunked bodies and bodies without Content-Length get 411, bodies over --max-body-mb
// get 413 before they are read (also instead of a 100 Continue), and nothing of a refused body
// is stored. Requests are written by hand, since cpp-httplib's client always frames its bodies.
#include <gtest/gtest.h>

#include <thread>

#include "http_test_support.h"
#include "sse_client.h"

namespace softshell {
namespace {

using namespace test;
using std::chrono::milliseconds;

constexpr size_t kLimit = size_t{1} << 20;

http::ServerOptions bodies_options() {
  http::ServerOptions o = test_server_options();
  o.max_body_bytes = kLimit;
  // Far longer than the test waits: an answer only after a read timeout would fail the test.
  o.io_timeout = std::chrono::seconds(120);
  return o;
}

// One answer read from a raw socket: its status, headers (lower-case names) and body.
struct RawAnswer {
  int status = 0;
  std::map<std::string, std::string> headers;
  std::string body;
  bool closed = false;  // the server closed the connection after the answer
  std::string raw;
};

// Reads one answer (status line, headers, Content-Length body), then whether the peer closes
// within `timeout`; gives up after `timeout`.
RawAnswer read_answer(int fd, milliseconds timeout) {
  RawAnswer a;
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  size_t head_end = std::string::npos, want = std::string::npos;
  while (std::chrono::steady_clock::now() < deadline) {
    if (want != std::string::npos && a.raw.size() >= want) break;
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    char buf[8192];
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) {
      a.closed = true;
      break;
    }
    a.raw.append(buf, static_cast<size_t>(n));
    if (head_end == std::string::npos && (head_end = a.raw.find("\r\n\r\n")) != std::string::npos) {
      a.status = std::atoi(a.raw.c_str() + a.raw.find(' ') + 1);
      for (size_t at = a.raw.find("\r\n") + 2; at < head_end;) {
        const size_t eol = a.raw.find("\r\n", at);
        const std::string line = a.raw.substr(at, eol - at);
        const size_t colon = line.find(':');
        std::string name = line.substr(0, colon);
        for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
        a.headers[name] = line.substr(line.find_first_not_of(' ', colon + 1));
        at = eol + 2;
      }
      want = head_end + 4 + (a.headers.count("content-length") ? std::stoul(a.headers["content-length"]) : 0);
    }
  }
  if (head_end != std::string::npos) a.body = a.raw.substr(head_end + 4, want - head_end - 4);
  // Then the connection should end (after the answer, at once).
  while (!a.closed && std::chrono::steady_clock::now() < deadline) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    char buf[8192];
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) a.closed = true;
    else a.raw.append(buf, static_cast<size_t>(n));
  }
  return a;
}

void send_all(int fd, const std::string& bytes) {
  size_t at = 0;
  while (at < bytes.size()) {
    const ssize_t n = ::send(fd, bytes.data() + at, bytes.size() - at, MSG_NOSIGNAL);
    if (n <= 0) return;  // the server may close before taking all of a refused body
    at += static_cast<size_t>(n);
  }
}

std::string mesh_bytes() { return wire::encode_geometry_binary(exact_grid(), exact_material()).value(); }

// A valid JSON mesh over kLimit (padded with whitespace), which uploads without the limit.
std::string json_mesh_over_limit() {
  std::string body = wire::encode_geometry_json(exact_grid(), exact_material());
  body.insert(1, kLimit + kLimit / 2, ' ');  // 1.5 MiB; whitespace inside the object is valid JSON
  return body;
}

std::string chunked(const std::string& body, size_t chunk) {
  std::string out;
  char size[32];
  for (size_t at = 0; at < body.size(); at += chunk) {
    const size_t n = std::min(chunk, body.size() - at);
    std::snprintf(size, sizeof size, "%zx\r\n", n);
    out.append(size).append(body, at, n).append("\r\n");
  }
  return out + "0\r\n\r\n";
}

void expect_error(const RawAnswer& a, int status, const std::string& code, const std::string& words) {
  EXPECT_EQ(a.status, status) << a.raw.substr(0, 400);
  EXPECT_EQ(a.headers.count("server") ? a.headers.at("server") : "", std::string("softshell/") + SOFTSHELL_VERSION_STRING) << a.raw.substr(0, 400);
  EXPECT_EQ(a.headers.count("connection") ? a.headers.at("connection") : "", "close");
  EXPECT_NE(a.body.find("{\"error\":\"" + code + "\""), std::string::npos) << a.raw.substr(0, 400);
  EXPECT_NE(a.body.find(words), std::string::npos) << a.body;
  EXPECT_TRUE(a.closed) << "the connection stays open after a refused body";
}

// Nothing was stored, and the server goes on serving.
void expect_nothing_stored(TestServer& server) {
  auto c = server.client();
  const Reply list = get(*c, "/geometries");
  EXPECT_EQ(list.status, 200);
  EXPECT_TRUE(wire::decode_geometry_list_json(list.body).value().empty()) << list.body;
  EXPECT_EQ(post(*c, "/geometries", mesh_bytes(), kBin).status, 201);
}

TEST(HttpBodiesTest, ChunkedBodiesAreRefusedWith411WhateverTheirSize) {
  TestServer server(test_service_options(), bodies_options());
  // One over the limit (the 201 the defect gave) and one small, valid one: both refused, unread.
  for (const std::string& body : {json_mesh_over_limit(), wire::encode_geometry_json(exact_grid(), exact_material())}) {
    const int fd = connect_loopback(server.port());
    ASSERT_GE(fd, 0);
    std::thread sender([&] {
      send_all(fd,
               "POST /geometries HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
               "Transfer-Encoding: chunked\r\n\r\n" +
                   chunked(body, 64 << 10));
    });
    const RawAnswer a = read_answer(fd, milliseconds(20000));
    sender.join();
    ::close(fd);
    expect_error(a, 411, "length_required", "Content-Length");
  }
  expect_nothing_stored(server);
}

TEST(HttpBodiesTest, ChunkedBodyWithExpectIsRefusedInsteadOf100) {
  TestServer server(test_service_options(), bodies_options());
  const int fd = connect_loopback(server.port());
  ASSERT_GE(fd, 0);
  send_all(fd,
           "PUT /geometries/0123/holds/h HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
           "Transfer-Encoding: chunked\r\nExpect: 100-continue\r\n\r\n");
  const RawAnswer a = read_answer(fd, milliseconds(20000));
  ::close(fd);
  expect_error(a, 411, "length_required", "Content-Length");
}

TEST(HttpBodiesTest, PostAndPutWithoutContentLengthGet411AtOnce) {
  TestServer server(test_service_options(), bodies_options());
  for (const std::string method : {"POST /geometries", "PUT /geometries/0123/holds/h"}) {
    const int fd = connect_loopback(server.port());
    ASSERT_GE(fd, 0);
    // The body follows, the connection stays open: the defect read until the peer closed.
    send_all(fd, method + " HTTP/1.1\r\nHost: x\r\nContent-Type: application/octet-stream\r\n\r\n" + mesh_bytes());
    const RawAnswer a = read_answer(fd, milliseconds(20000));
    ::close(fd);
    expect_error(a, 411, "length_required", "needs a Content-Length header");
  }
  expect_nothing_stored(server);
}

TEST(HttpBodiesTest, DeleteWithoutContentLengthHasAnEmptyBody) {
  TestServer server(test_service_options(), bodies_options());
  const int fd = connect_loopback(server.port());
  ASSERT_GE(fd, 0);
  // As curl -X DELETE sends it; answered at once, and the connection serves the next request.
  send_all(fd,
           "DELETE /geometries/0123/holds/h HTTP/1.1\r\nHost: x\r\n\r\n"
           "GET /health HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n");
  const RawAnswer first = read_answer(fd, milliseconds(20000));
  ::close(fd);
  // The route's own answer for an unknown geometry, not a framing error.
  EXPECT_TRUE(first.status == 400 || first.status == 404) << first.raw;
  EXPECT_EQ(first.body.find("Content-Length"), std::string::npos) << first.body;
  EXPECT_NE(first.raw.find("HTTP/1.1 200"), std::string::npos) << "the next request was not served: " << first.raw;
}

TEST(HttpBodiesTest, ContentLengthOverTheLimitGets413BeforeTheBodyIsRead) {
  TestServer server(test_service_options(), bodies_options());
  const int fd = connect_loopback(server.port());
  ASSERT_GE(fd, 0);
  // 2 GiB announced, a few bytes sent: the defect read (skipped) all of it before answering.
  send_all(fd,
           "POST /geometries HTTP/1.1\r\nHost: x\r\nContent-Type: application/octet-stream\r\n"
           "Content-Length: 2147483648\r\n\r\nSSGM");
  const RawAnswer a = read_answer(fd, milliseconds(20000));
  ::close(fd);
  expect_error(a, 413, "payload_too_large", "--max-body-mb");
  expect_nothing_stored(server);
}

TEST(HttpBodiesTest, BadContentLengthIs400) {
  TestServer server(test_service_options(), bodies_options());
  for (const std::string header : {"Content-Length: 12abc\r\n", "Content-Length: 4\r\nContent-Length: 5\r\n"}) {
    const int fd = connect_loopback(server.port());
    ASSERT_GE(fd, 0);
    send_all(fd, "POST /geometries HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n" + header + "\r\n{}");
    const RawAnswer a = read_answer(fd, milliseconds(20000));
    ::close(fd);
    expect_error(a, 400, "invalid_argument", "Content-Length");
  }
}

TEST(HttpBodiesTest, ExpectContinueOverTheLimitGets413InsteadOf100) {
  TestServer server(test_service_options(), bodies_options());
  const int fd = connect_loopback(server.port());
  ASSERT_GE(fd, 0);
  send_all(fd,
           "POST /geometries HTTP/1.1\r\nHost: x\r\nContent-Type: application/octet-stream\r\n"
           "Content-Length: 2147483648\r\nExpect: 100-continue\r\n\r\n");
  const RawAnswer a = read_answer(fd, milliseconds(20000));
  ::close(fd);
  EXPECT_EQ(a.raw.find("100 Continue"), std::string::npos) << a.raw;
  expect_error(a, 413, "payload_too_large", "--max-body-mb");
}

TEST(HttpBodiesTest, ExpectContinueWithinTheLimitGets100ThenTheAnswer) {
  TestServer server(test_service_options(), bodies_options());
  const int fd = connect_loopback(server.port());
  ASSERT_GE(fd, 0);
  const std::string body = mesh_bytes();
  send_all(fd,
           "POST /geometries HTTP/1.1\r\nHost: x\r\nContent-Type: application/octet-stream\r\n"
           "Content-Length: " +
               std::to_string(body.size()) + "\r\nExpect: 100-continue\r\nConnection: close\r\n\r\n");
  // The 100 comes before any of the body is sent.
  std::string interim;
  const auto deadline = std::chrono::steady_clock::now() + milliseconds(20000);
  while (interim.find("\r\n\r\n") == std::string::npos && std::chrono::steady_clock::now() < deadline) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    char buf[256];
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) break;
    interim.append(buf, static_cast<size_t>(n));
  }
  EXPECT_EQ(interim.rfind("HTTP/1.1 100 Continue\r\n", 0), 0u) << interim;
  send_all(fd, body);
  const RawAnswer a = read_answer(fd, milliseconds(20000));
  ::close(fd);
  EXPECT_EQ(a.status, 201) << a.raw.substr(0, 400);
}

}  // namespace
}  // namespace softshell
