// docs/deploy/nginx.conf in front of a softshell server, on loopback: nginx (Debian's package,
// run as a child process with the documented file, its ports, paths and body limit replaced,
// everything else as written) terminates TLS, passes event streams through unbuffered, and
// takes the slowloris, huge-header and chunked-body attacks itself while a normal client is
// still served. Skipped when nginx is not installed (build.sh: EXTRA_PACKAGES=nginx).
#include <gtest/gtest.h>

#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "http_test_support.h"
#include "sse_client.h"

namespace softshell {
namespace {

using namespace test;
using std::chrono::milliseconds;

constexpr const char* kToken = "nginx-token-0123456789abcdef";

std::string find_nginx() {
  for (const char* p : {"/usr/sbin/nginx", "/usr/local/sbin/nginx", "/usr/bin/nginx"}) {
    if (::access(p, X_OK) == 0) return p;
  }
  return {};
}

// A port nothing listens on right now (bound to port 0, then released).
int free_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) return 0;
  socklen_t n = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n);
  ::close(fd);
  return ntohs(a.sin_port);
}

// Replaces `from` (which must occur) by `to` in `text`.
void replace(std::string& text, const std::string& from, const std::string& to) {
  const size_t at = text.find(from);
  ASSERT_NE(at, std::string::npos) << "docs/deploy/nginx.conf no longer has: " << from;
  text.replace(at, from.size(), to);
}

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Everything one connection gets within `timeout` (until the peer closes).
std::string drain(int fd, milliseconds timeout) {
  std::string out;
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    char buf[8192];
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) break;
    out.append(buf, static_cast<size_t>(n));
  }
  return out;
}

int status_of(const std::string& answer) { return answer.size() > 12 ? std::atoi(answer.c_str() + 9) : 0; }

class NginxProxyTest : public ::testing::Test {
 protected:
  void SetUp() override {
    nginx_ = find_nginx();
    if (nginx_.empty()) GTEST_SKIP() << "nginx is not installed (Debian package nginx)";
    http::ServerOptions o = test_server_options();
    o.auth_token = kToken;
    o.max_body_bytes = size_t{1} << 20;
    o.max_connections = 32;  // direct, 100 slow connections would leave nobody served (issue 17)
    server_ = std::make_unique<TestServer>(test_service_options(), o);

    char dir_template[] = "/tmp/softshell_nginx_XXXXXX";
    ASSERT_NE(::mkdtemp(dir_template), nullptr);
    dir_ = dir_template;
    tls_ = std::system(("openssl req -x509 -newkey rsa:2048 -nodes -days 1 -subj /CN=localhost -addext "
                        "subjectAltName=DNS:localhost -keyout " + dir_ + "/key.pem -out " + dir_ +
                        "/cert.pem >/dev/null 2>&1").c_str()) == 0;
    plain_port_ = free_port();
    tls_port_ = free_port();
    ASSERT_GT(plain_port_, 0);

    std::string site = read_text(SOFTSHELL_NGINX_CONF);
    ASSERT_FALSE(site.empty()) << SOFTSHELL_NGINX_CONF;
    replace(site, "server 127.0.0.1:8080;", "server 127.0.0.1:" + std::to_string(server_->port()) + ";");
    // Plain HTTP beside TLS, for the raw-socket attacks (the same server block and limits).
    replace(site, "listen 443 ssl;", (tls_ ? "listen 127.0.0.1:" + std::to_string(tls_port_) + " ssl;\n    " : "") +
                                         "listen 127.0.0.1:" + std::to_string(plain_port_) + ";");
    replace(site, "/etc/softshell/tls/cert.pem", dir_ + "/cert.pem");
    replace(site, "/etc/softshell/tls/key.pem", dir_ + "/key.pem");
    if (!tls_) {  // no openssl: the TLS lines go (their paths would not exist)
      for (const char* d : {"ssl_certificate ", "ssl_certificate_key "}) {
        const size_t at = site.find(std::string("    ") + d);
        site.erase(at, site.find('\n', at) - at + 1);
      }
    }
    replace(site, "/var/log/nginx/softshell.access.log", dir_ + "/access.log");
    replace(site, "client_max_body_size        64m;", "client_max_body_size        1m;");
    std::ofstream(dir_ + "/softshell.conf") << site;
    std::ofstream(dir_ + "/nginx.conf")
        << "daemon off;\nmaster_process off;\npid " << dir_ << "/nginx.pid;\nerror_log " << dir_
        << "/error.log warn;\nevents { worker_connections 4096; }\nhttp {\n"
        << "  client_body_temp_path " << dir_ << "/body;\n  proxy_temp_path " << dir_ << "/proxy;\n"
        << "  fastcgi_temp_path " << dir_ << "/fastcgi;\n  uwsgi_temp_path " << dir_ << "/uwsgi;\n"
        << "  scgi_temp_path " << dir_ << "/scgi;\n  include " << dir_ << "/softshell.conf;\n}\n";

    pid_ = ::fork();
    if (pid_ == 0) {
      const int null = ::open("/dev/null", O_WRONLY);
      ::dup2(null, 1);
      ::dup2(null, 2);
      ::execl(nginx_.c_str(), nginx_.c_str(), "-p", (dir_ + "/").c_str(), "-e", (dir_ + "/error.log").c_str(), "-c",
              (dir_ + "/nginx.conf").c_str(), static_cast<char*>(nullptr));
      ::_exit(127);
    }
    ASSERT_GT(pid_, 0);
    for (int i = 0; i < 200; ++i) {
      const int fd = connect_loopback(plain_port_);
      if (fd >= 0) {
        ::close(fd);
        return;
      }
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        FAIL() << "nginx exited: " << read_text(dir_ + "/error.log");
      }
      std::this_thread::sleep_for(milliseconds(50));
    }
    FAIL() << "nginx did not listen: " << read_text(dir_ + "/error.log");
  }

  void TearDown() override {
    if (pid_ > 0) {
      ::kill(pid_, SIGTERM);
      ::waitpid(pid_, nullptr, 0);
    }
    if (!dir_.empty()) std::filesystem::remove_all(dir_);
  }

  std::unique_ptr<httplib::Client> proxied() const {
    auto c = std::make_unique<httplib::Client>("127.0.0.1", plain_port_);
    c->set_read_timeout(30, 0);
    c->set_bearer_token_auth(kToken);
    return c;
  }

  // A normal client's round trip through nginx.
  bool served() const {
    auto r = proxied()->Get("/geometries");
    return r && r->status == 200;
  }

  std::string nginx_, dir_;
  bool tls_ = false;
  int plain_port_ = 0, tls_port_ = 0;
  pid_t pid_ = -1;
  std::unique_ptr<TestServer> server_;
};

TEST_F(NginxProxyTest, PassesTheApiTokenAndEventStreams) {
  auto c = proxied();
  auto up = c->Post("/geometries", {{"Accept", kJson}}, wire::encode_geometry_binary(exact_grid(), exact_material()).value(),
                    kBin);
  ASSERT_TRUE(up);
  ASSERT_EQ(up->status, 201) << up->body;
  const std::string id = wire::decode_upload_response_json(up->body, true).value().id.hex();
  httplib::Client anonymous("127.0.0.1", plain_port_);
  auto refused = anonymous.Get("/geometries");
  ASSERT_TRUE(refused);
  EXPECT_EQ(refused->status, 401);
  EXPECT_EQ(refused->get_header_value("WWW-Authenticate"), R"(Bearer realm="softshell")");

  // An event through nginx arrives while the stream stays open (not held in a buffer).
  ASSERT_TRUE(server_->service().wait_until_precomputed(GeomId::from_hex(id).value(), std::chrono::seconds(60)));
  SseClient s(plain_port_, "/geometries/" + id + "/events", {std::string("Authorization: Bearer ") + kToken});
  ASSERT_TRUE(s.read_head(milliseconds(10000)));
  EXPECT_EQ(s.parser().status(), 200);
  DeformationRequest request;
  request.vertex_constraints = pinned_corners(4);
  request.forces.push_back({grid_index(4, 2, 2), Vec3(0.0, 0.0, -0.25)});
  auto posted = c->Post("/geometries/" + id + "/results", wire::encode_request_json(request), kJson);
  ASSERT_TRUE(posted);
  ASSERT_EQ(posted->status, 200) << posted->body;
  bool got = false;
  for (int i = 0; i < 10 && !got; ++i) {
    auto e = s.next(milliseconds(5000));
    got = e && e->event == "result";
  }
  EXPECT_TRUE(got) << "no result event through nginx";

  // TLS termination with the test's own certificate.
  if (!tls_) GTEST_SKIP() << "no openssl: TLS not checked";
  const std::string cmd = "curl -s -o /dev/null -w '%{http_code}' --cacert " + dir_ + "/cert.pem --resolve localhost:" +
                          std::to_string(tls_port_) + ":127.0.0.1 -H 'Authorization: Bearer " + kToken +
                          "' https://localhost:" + std::to_string(tls_port_) + "/geometries";
  FILE* p = ::popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  char code[16] = {};
  const size_t n = std::fread(code, 1, sizeof code - 1, p);
  ::pclose(p);
  EXPECT_EQ(std::string(code, n), "200") << cmd;
}

// 200 connections trickle header lines; through nginx, the normal client is served all along and
// softshell-server (at --max-connections 32) never sees them.
TEST_F(NginxProxyTest, SlowlorisIsHeldByNginx) {
  std::vector<int> slow;
  for (int i = 0; i < 200; ++i) {
    const int fd = connect_loopback(plain_port_);
    ASSERT_GE(fd, 0);
    const std::string head = "GET /geometries HTTP/1.1\r\nHost: 127.0.0.1\r\n";
    (void)!::send(fd, head.data(), head.size(), MSG_NOSIGNAL);
    slow.push_back(fd);
  }
  int normal = 0, ok = 0;
  for (int round = 0; round < 6; ++round) {
    for (int fd : slow) (void)!::send(fd, "X-Slow: 1\r\n", 11, MSG_NOSIGNAL);
    ++normal;
    ok += served() ? 1 : 0;
    EXPECT_LT(server_->http().busy_connections(), 8) << "slow connections reached softshell-server";
    std::this_thread::sleep_for(milliseconds(300));
  }
  EXPECT_EQ(ok, normal);
  for (int fd : slow) ::close(fd);
}

TEST_F(NginxProxyTest, HugeHeadersAndChunkedBodiesStopAtNginx) {
  const std::string auth = std::string("Authorization: Bearer ") + kToken + "\r\n";
  // One 64 KiB header line, then 64 lines of 8 KiB: 400 from nginx, connection closed.
  for (const std::string& headers :
       {"X-Big: " + std::string(64 << 10, 'a') + "\r\n", [] {
          std::string many;
          for (int i = 0; i < 64; ++i) many += "X-Line-" + std::to_string(i) + ": " + std::string(8000, 'b') + "\r\n";
          return many;
        }()}) {
    const int fd = connect_loopback(plain_port_);
    ASSERT_GE(fd, 0);
    const std::string request = "GET /geometries HTTP/1.1\r\nHost: 127.0.0.1\r\n" + auth + headers + "\r\n";
    (void)!::send(fd, request.data(), request.size(), MSG_NOSIGNAL);
    const std::string answer = drain(fd, milliseconds(10000));
    ::close(fd);
    EXPECT_EQ(status_of(answer), 400) << answer.substr(0, 200);
    EXPECT_TRUE(served());
  }

  // A chunked body over the limit: 413 from nginx (softshell-server never buffers it).
  {
    const int fd = connect_loopback(plain_port_);
    ASSERT_GE(fd, 0);
    std::string request = "POST /geometries HTTP/1.1\r\nHost: 127.0.0.1\r\n" + auth +
                          "Content-Type: application/octet-stream\r\nTransfer-Encoding: chunked\r\n\r\n";
    const std::string chunk(64 << 10, 'x');
    char size[16];
    std::snprintf(size, sizeof size, "%zx\r\n", chunk.size());
    for (int i = 0; i < 32; ++i) request += size + chunk + "\r\n";  // 2 MiB
    request += "0\r\n\r\n";
    (void)!::send(fd, request.data(), request.size(), MSG_NOSIGNAL);
    const std::string answer = drain(fd, milliseconds(10000));
    ::close(fd);
    EXPECT_EQ(status_of(answer), 413) << answer.substr(0, 200);
  }
  // A chunked body within it: nginx forwards it with a Content-Length, softshell stores it.
  {
    const std::string mesh = wire::encode_geometry_binary(exact_grid(), exact_material()).value();
    const int fd = connect_loopback(plain_port_);
    ASSERT_GE(fd, 0);
    char size[16];
    std::snprintf(size, sizeof size, "%zx\r\n", mesh.size());
    const std::string request = "POST /geometries HTTP/1.1\r\nHost: 127.0.0.1\r\n" + auth +
                                "Content-Type: application/octet-stream\r\nTransfer-Encoding: chunked\r\n"
                                "Connection: close\r\n\r\n" +
                                size + mesh + "\r\n0\r\n\r\n";
    (void)!::send(fd, request.data(), request.size(), MSG_NOSIGNAL);
    const std::string answer = drain(fd, milliseconds(10000));
    ::close(fd);
    EXPECT_EQ(status_of(answer), 201) << answer.substr(0, 300);
  }
  EXPECT_EQ(server_->service().geometries().size(), 1u);
  EXPECT_TRUE(served());
}

}  // namespace
}  // namespace softshell
