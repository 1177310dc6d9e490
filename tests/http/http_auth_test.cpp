// Access tokens (ServerOptions::auth_token, --auth-token-file) on real sockets: 401 without the
// right `Authorization: Bearer` header, the exempt requests (/health, the browser app's files,
// CORS preflights), no limit told before the token is checked, event streams, the SDK's remote
// session and the C ABI's remote options, and the token file's checks.
#include <gtest/gtest.h>

#include <sys/stat.h>

#include <cstdio>
#include <filesystem>
#include <poll.h>
#include <fstream>

#include "http_test_support.h"
#include "softshell/http/auth.h"
#include "softshell/remote_session.h"
#include "softshell/softshell_c.h"
#include "sse_client.h"

namespace softshell {
namespace {

using namespace test;
using std::chrono::milliseconds;

constexpr const char* kToken = "s3cret-token-0123456789abcdef";

http::ServerOptions auth_options() {
  http::ServerOptions o = test_server_options();
  o.auth_token = kToken;
  o.max_body_bytes = size_t{1} << 20;
  o.cors_origins = {"http://app.example"};
  return o;
}

httplib::Headers bearer(const std::string& token) { return {{"Authorization", "Bearer " + token}}; }

// Sends `request` on a new connection and reads until the server closes it or `timeout` passes.
struct RawExchange {
  std::string answer;
  bool closed = false;
  int status() const { return answer.size() > 12 ? std::atoi(answer.c_str() + 9) : 0; }
};
RawExchange raw_exchange(int port, const std::string& request, milliseconds timeout = milliseconds(10000)) {
  RawExchange out;
  const int fd = connect_loopback(port);
  if (fd < 0) return out;
  (void)!::send(fd, request.data(), request.size(), MSG_NOSIGNAL);
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    char buf[4096];
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) {
      out.closed = true;
      break;
    }
    out.answer.append(buf, static_cast<size_t>(n));
  }
  ::close(fd);
  return out;
}

TEST(HttpAuthTest, EveryRequestButTheExemptOnesNeedsTheToken) {
  TestServer server(test_service_options(), auth_options());
  auto c = server.client();

  // No token, a wrong one, a prefix of the right one, another scheme: 401 with the challenge.
  struct Case {
    httplib::Headers headers;
    const char* challenge;
    const char* says;
  };
  const std::string longer = std::string(kToken) + "x";
  const std::string prefix = std::string(kToken).substr(0, 20);
  for (const Case& k : {Case{{}, R"(Bearer realm="softshell")", "Authorization: Bearer <token>"},
                        Case{bearer("wrong-token-0123456789"), R"(Bearer realm="softshell", error="invalid_token")",
                             "not this server's"},
                        Case{bearer(prefix), R"(Bearer realm="softshell", error="invalid_token")", "not this server's"},
                        Case{bearer(longer), R"(Bearer realm="softshell", error="invalid_token")", "not this server's"},
                        Case{{{"Authorization", std::string("Basic ") + kToken}}, R"(Bearer realm="softshell")",
                             "'Bearer <token>'"},
                        Case{{{"Authorization", "Bearer "}}, R"(Bearer realm="softshell")", "'Bearer <token>'"}}) {
    for (const char* path : {"/geometries", "/metrics", "/geometries/00000000000000000000000000000000/status"}) {
      auto r = c->Get(path, k.headers);
      ASSERT_TRUE(r);
      EXPECT_EQ(r->status, 401) << path;
      EXPECT_EQ(r->get_header_value("WWW-Authenticate"), k.challenge) << path;
      EXPECT_NE(r->body.find(R"({"error":"unauthenticated","message":)"), std::string::npos) << r->body;
      EXPECT_NE(r->body.find(k.says), std::string::npos) << r->body;
      EXPECT_EQ(r->get_header_value("Server").rfind("softshell", 0), 0u);
    }
  }
  // The right token; the scheme's name in any case, spaces around the token.
  auto ok = c->Get("/geometries", bearer(kToken));
  ASSERT_TRUE(ok);
  EXPECT_EQ(ok->status, 200);
  auto lower = c->Get("/metrics", {{"Authorization", std::string("bearer  ") + kToken + " "}});
  ASSERT_TRUE(lower);
  EXPECT_EQ(lower->status, 200);
  // Two Authorization headers are refused even when one is right.
  httplib::Headers two = bearer(kToken);
  two.emplace("Authorization", "Bearer other-token-0123456789");
  auto twice = c->Get("/geometries", two);
  ASSERT_TRUE(twice);
  EXPECT_EQ(twice->status, 401);

  // Exempt: liveness, the browser app's files, CORS preflights.
  for (const char* path : {"/health", "/", "/index.html", "/app/client.js"}) {
    auto r = c->Get(path);
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 200) << path;
  }
  auto head = c->Head("/health");
  ASSERT_TRUE(head);
  EXPECT_EQ(head->status, 200);
  auto preflight = c->Options("/geometries", {{"Origin", "http://app.example"},
                                              {"Access-Control-Request-Method", "POST"},
                                              {"Access-Control-Request-Headers", "authorization, content-type"}});
  ASSERT_TRUE(preflight);
  EXPECT_EQ(preflight->status, 204);
  EXPECT_NE(preflight->get_header_value("Access-Control-Allow-Headers").find("Authorization"), std::string::npos);
  // A cross-origin 401 can be read by the page (its challenge header is exposed).
  auto cross = c->Get("/geometries", {{"Origin", "http://app.example"}});
  ASSERT_TRUE(cross);
  EXPECT_EQ(cross->status, 401);
  EXPECT_EQ(cross->get_header_value("Access-Control-Allow-Origin"), "http://app.example");
  EXPECT_NE(cross->get_header_value("Access-Control-Expose-Headers").find("WWW-Authenticate"), std::string::npos);

  // An upload needs the token; with it, it is stored.
  const std::string mesh = wire::encode_geometry_binary(exact_grid(), exact_material()).value();
  auto anonymous = c->Post("/geometries", mesh, kBin);
  ASSERT_TRUE(anonymous);
  EXPECT_EQ(anonymous->status, 401);
  EXPECT_EQ(server.service().geometries().size(), 0u);
  auto up = c->Post("/geometries", bearer(kToken), mesh, kBin);
  ASSERT_TRUE(up);
  EXPECT_EQ(up->status, 201) << up->body;
  EXPECT_EQ(server.service().geometries().size(), 1u);
  // The token is never taken from the URL.
  auto query = c->Get(std::string("/geometries?access_token=") + kToken);
  ASSERT_TRUE(query);
  EXPECT_EQ(query->status, 401);
}

// The token is checked before anything else: a client without it learns no limit (no 413, 411
// or 100 Continue), and the connection of a request whose body stays unread ends after the 401.
TEST(HttpAuthTest, NoLimitIsToldBeforeTheToken) {
  TestServer server(test_service_options(), auth_options());
  const int port = server.port();
  const std::string head = "POST /geometries HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/octet-stream\r\n";
  for (const std::string& request :
       {head + "Content-Length: 999999999\r\n\r\n",                             // over --max-body-mb: 413 with the token
        head + "Transfer-Encoding: chunked\r\n\r\n10\r\n0123456789abcdef\r\n",  // chunked: 411 with the token
        head + "Content-Length: 100\r\nExpect: 100-continue\r\n\r\n",           // would get 100 Continue
        head + "Content-Length: 5000000\r\nExpect: 100-continue\r\n\r\n",       // would get 413
        head + "Content-Encoding: gzip\r\nContent-Length: 10\r\n\r\n0123456789"}) {
    const RawExchange r = raw_exchange(port, request);
    EXPECT_EQ(r.status(), 401) << r.answer;
    EXPECT_TRUE(r.closed) << "the connection stays open after a 401 with an unread body";
    EXPECT_EQ(r.answer.find("100 Continue"), std::string::npos) << r.answer;
    EXPECT_EQ(r.answer.find("MiB"), std::string::npos) << r.answer;
    EXPECT_NE(r.answer.find("WWW-Authenticate: Bearer realm=\"softshell\""), std::string::npos) << r.answer;
  }
  // With the token, the same requests get the limits' answers.
  const std::string auth = std::string("Authorization: Bearer ") + kToken + "\r\n";
  EXPECT_EQ(raw_exchange(port, head + auth + "Content-Length: 999999999\r\n\r\n").status(), 413);
  EXPECT_EQ(raw_exchange(port, head + auth + "Transfer-Encoding: chunked\r\n\r\n").status(), 411);
  // A request without a body keeps its keep-alive connection after the 401.
  auto c = server.client();
  auto first = c->Get("/geometries");
  ASSERT_TRUE(first);
  EXPECT_EQ(first->status, 401);
  EXPECT_NE(first->get_header_value("Connection"), "close");
}

TEST(HttpAuthTest, EventStreamsNeedTheToken) {
  TestServer server(test_service_options(), auth_options());
  RemoteSessionOptions o;
  o.auth_token = kToken;
  RemoteSession session(server.url(), o);
  auto up = session.upload(exact_grid(), exact_material());
  ASSERT_TRUE(up) << up.error().message;
  const std::string path = "/geometries/" + up->id.hex() + "/events";
  {
    SseClient anonymous(server.port(), path);
    ASSERT_TRUE(anonymous.read_head(milliseconds(10000)));
    EXPECT_EQ(anonymous.parser().status(), 401);
    EXPECT_EQ(anonymous.parser().header("WWW-Authenticate"), R"(Bearer realm="softshell")");
    SseClient in_url(server.port(), path + "?access_token=" + kToken);
    ASSERT_TRUE(in_url.read_head(milliseconds(10000)));
    EXPECT_EQ(in_url.parser().status(), 401);
  }
  SseClient s(server.port(), path, {std::string("Authorization: Bearer ") + kToken});
  ASSERT_TRUE(s.read_head(milliseconds(10000)));
  EXPECT_EQ(s.parser().status(), 200);
  EXPECT_EQ(s.parser().header("Content-Type").rfind("text/event-stream", 0), 0u);
  ASSERT_TRUE(session.deform(up->id, pinned_push(1)));
  bool got = false;
  for (int i = 0; i < 10 && !got; ++i) {
    auto e = s.next(milliseconds(5000));
    got = e && e->event == "result";
  }
  EXPECT_TRUE(got) << "no result event on the authenticated stream";
}

TEST(HttpAuthTest, RemoteSessionSendsItsToken) {
  TestServer server(test_service_options(), auth_options());
  RemoteSessionOptions with;
  with.auth_token = kToken;
  with.events_retry_min = milliseconds(20);
  RemoteSession session(server.url(), with);
  auto up = session.upload(exact_grid(), exact_material());
  ASSERT_TRUE(up) << up.error().message;
  ASSERT_TRUE(server.service().wait_until_precomputed(up->id, std::chrono::seconds(60)));
  auto sub = session.subscribe(up->id);
  ASSERT_TRUE(sub) << sub.error().message;
  auto r = session.deform(up->id, pinned_push(1));
  ASSERT_TRUE(r) << r.error().message;
  auto event = (*sub)->next(milliseconds(20000));
  ASSERT_TRUE(event) << event.error().message;
  ASSERT_TRUE(event->has_value());
  EXPECT_EQ((*event)->result.res_id, r->res_id);
  auto listed = session.geometries();
  ASSERT_TRUE(listed) << listed.error().message;
  EXPECT_EQ(listed->size(), 1u);

  // Without a token, and with a wrong one: connect works (/health is open), every call after it
  // is refused (kInvalidArgument, as every refused request) with a message that says where the
  // token goes; a subscription fails at once.
  for (const std::string& token : {std::string(), std::string("not-the-token-0123456789")}) {
    RemoteSessionOptions o;
    o.auth_token = token;
    auto other = RemoteSession::connect(server.url(), o);
    ASSERT_TRUE(other) << other.error().message;
    auto status = (*other)->geometry_info(up->id);
    ASSERT_FALSE(status);
    EXPECT_EQ(status.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(status.error().message.find("RemoteSessionOptions::auth_token"), std::string::npos)
        << status.error().message;
    auto deform = (*other)->deform(up->id, pinned_push(2));
    ASSERT_FALSE(deform);
    EXPECT_EQ(deform.error().code, ErrorCode::kInvalidArgument);
    auto denied = (*other)->subscribe(up->id);
    ASSERT_FALSE(denied);
    EXPECT_EQ(denied.error().code, ErrorCode::kInvalidArgument) << denied.error().message;
  }
  EXPECT_EQ(server.service().geometries().size(), 1u);
}

TEST(HttpAuthTest, CRemoteOptionsCarryTheToken) {
  TestServer server(test_service_options(), auth_options());
  ss_remote_options o;
  ss_remote_options_default(&o);
  EXPECT_EQ(o.auth_token, nullptr);
  EXPECT_EQ(ss_abi_version(), 4u);

  // A 4 x 4 grid of quads over [0, 1]^2.
  constexpr int n = 4;
  std::vector<double> xyz;
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) xyz.insert(xyz.end(), {double(i) / n, double(j) / n, 0.0});
  }
  std::vector<int32_t> sizes(n * n, 4), indices;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      indices.insert(indices.end(), {grid_index(n, i, j), grid_index(n, i + 1, j), grid_index(n, i + 1, j + 1),
                                     grid_index(n, i, j + 1)});
    }
  }
  ss_mesh* mesh = nullptr;
  ASSERT_EQ(ss_mesh_create(xyz.data(), (n + 1) * (n + 1), sizes.data(), n * n, indices.data(),
                           static_cast<int32_t>(indices.size()), &mesh),
            SS_OK)
      << ss_last_error_message();
  ss_material material;
  ss_material_default(&material);
  ss_geom_id id{};

  // No token, then an empty one: refused (SS_INVALID_ARGUMENT) with the server's message.
  for (const char* token : {static_cast<const char*>(nullptr), ""}) {
    o.auth_token = token;
    ss_session* anonymous = nullptr;
    ASSERT_EQ(ss_session_create_remote(server.url().c_str(), &o, &anonymous), SS_OK) << ss_last_error_message();
    EXPECT_EQ(ss_session_upload(anonymous, mesh, &material, nullptr, &id, nullptr), SS_INVALID_ARGUMENT);
    EXPECT_NE(std::string(ss_last_error_message()).find("Authorization: Bearer"), std::string::npos)
        << ss_last_error_message();
    ss_session_destroy(anonymous);
  }
  // The token, copied in: the caller's buffer may go away after create.
  std::string token = kToken;
  o.auth_token = token.c_str();
  ss_session* session = nullptr;
  ASSERT_EQ(ss_session_create_remote(server.url().c_str(), &o, &session), SS_OK) << ss_last_error_message();
  token.assign(token.size(), 'x');
  int32_t created = 0;
  EXPECT_EQ(ss_session_upload(session, mesh, &material, nullptr, &id, &created), SS_OK) << ss_last_error_message();
  EXPECT_EQ(created, 1);
  EXPECT_EQ(server.service().geometries().size(), 1u);
  ss_session_destroy(session);
  ss_mesh_destroy(mesh);
}

TEST(HttpAuthTest, StartRefusesAWeakToken) {
  for (const char* weak : {"short", "has a space in it 0123", "tab\there-0123456789"}) {
    http::ServerOptions o = test_server_options();
    o.auth_token = weak;
    http::HttpServer server(std::make_shared<service::Service>(test_service_options()), o);
    auto started = server.start("127.0.0.1", 0);
    ASSERT_FALSE(started) << weak;
    EXPECT_EQ(started.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(started.error().message.find("auth_token"), std::string::npos) << started.error().message;
  }
}

class TokenFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir = std::filesystem::temp_directory_path() /
          ("softshell_auth_" + std::to_string(::getpid()) + "_" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir);
  }
  void TearDown() override { std::filesystem::remove_all(dir); }
  std::string write(const std::string& name, const std::string& text, mode_t mode = 0600) {
    const std::string path = (dir / name).string();
    std::ofstream(path, std::ios::binary) << text;
    ::chmod(path.c_str(), mode);
    return path;
  }
  std::filesystem::path dir;
};

TEST_F(TokenFileTest, ReadsOneTokenAndRefusesBadFiles) {
  auto ok = http::read_auth_token_file(write("ok", std::string(kToken) + "\r\n \n"));
  ASSERT_TRUE(ok) << ok.error().message;
  EXPECT_EQ(ok->token, kToken);
  EXPECT_TRUE(ok->warnings.empty());

  auto shared = http::read_auth_token_file(write("shared", kToken, 0644));
  ASSERT_TRUE(shared);
  ASSERT_EQ(shared->warnings.size(), 1u);
  EXPECT_NE(shared->warnings[0].find("chmod 600"), std::string::npos) << shared->warnings[0];
  auto group = http::read_auth_token_file(write("group", kToken, 0640));
  ASSERT_TRUE(group);
  ASSERT_EQ(group->warnings.size(), 1u);
  EXPECT_NE(group->warnings[0].find("group"), std::string::npos);

  struct Bad {
    std::string path;
    ErrorCode code;
    const char* says;
  };
  const std::vector<Bad> bad{
      {(dir / "missing").string(), ErrorCode::kIoError, "does not exist"},
      {dir.string(), ErrorCode::kInvalidArgument, "not a regular file"},
      {write("empty", ""), ErrorCode::kInvalidArgument, "empty"},
      {write("blank", "\n\n  \n"), ErrorCode::kInvalidArgument, "empty"},
      {write("short", "0123456789abcde\n"), ErrorCode::kInvalidArgument, "15 characters; at least 16"},
      {write("two words", "0123456789 abcdef0123\n"), ErrorCode::kInvalidArgument, "position 11"},
      {write("leading", " 0123456789abcdef0123\n"), ErrorCode::kInvalidArgument, "position 1"},
      {write("two lines", "0123456789abcdef\n0123456789abcdef\n"), ErrorCode::kInvalidArgument, "visible ASCII"},
      {write("utf8", "0123456789abcdef\xc3\xa9"), ErrorCode::kInvalidArgument, "visible ASCII"},
      {write("huge", std::string(5000, 'a')), ErrorCode::kInvalidArgument, "larger than 4096 bytes"},
  };
  for (const Bad& b : bad) {
    auto r = http::read_auth_token_file(b.path);
    ASSERT_FALSE(r) << b.path;
    EXPECT_EQ(r.error().code, b.code) << b.path << ": " << r.error().message;
    EXPECT_NE(r.error().message.find(b.says), std::string::npos) << r.error().message;
    EXPECT_NE(r.error().message.find(b.path), std::string::npos) << r.error().message;
  }
  if (::geteuid() != 0) {  // root reads any file
    auto locked = http::read_auth_token_file(write("locked", kToken, 0000));
    ASSERT_FALSE(locked);
    EXPECT_EQ(locked.error().code, ErrorCode::kIoError);
    EXPECT_NE(locked.error().message.find("cannot be read"), std::string::npos) << locked.error().message;
  }
}

}  // namespace
}  // namespace softshell
