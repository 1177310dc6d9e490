#pragma once
// An in-process softshell server on 127.0.0.1 (ephemeral port) for the HTTP and embedded tests,
// and raw-request helpers (cpp-httplib's client, so tests see exactly what goes over the wire).

#include <gtest/gtest.h>

#include <bit>
#include <memory>
#include <string>

#include "server_test_support.h"
#include "softshell/http/server.h"
#include "softshell/service/service.h"
#include "softshell/wire.h"

// Last: glibc's <resolv.h>, which httplib.h pulls in, defines a macro `_res` that breaks Eigen
// headers included after it.
#include <httplib.h>

namespace softshell::test {

inline service::ServiceOptions test_service_options() {
  service::ServiceOptions o;
  o.precompute_threads = 1;
  o.store_bytes = size_t{512} << 20;
  o.cache_bytes = size_t{64} << 20;
  return o;
}

inline http::ServerOptions test_server_options() {
  http::ServerOptions o;
  o.max_body_bytes = size_t{4} << 20;
  o.keep_alive_timeout = std::chrono::seconds(1);
  return o;
}

/// A service and its HTTP server on 127.0.0.1:<free port>, stopped by the destructor.
class TestServer {
 public:
  explicit TestServer(service::ServiceOptions so = test_service_options(),
                      http::ServerOptions ho = test_server_options())
      : service_(std::make_shared<service::Service>(std::move(so))), server_(service_, std::move(ho)) {
    auto bound = server_.start("127.0.0.1", 0);
    if (!bound) throw Exception(bound.error());
    port_ = *bound;
    // One request from this thread first. cpp-httplib's client initializes function-local
    // statics (regexes) on first use inside its uninstrumented shared library; doing that here,
    // before a test starts threads, orders it before every later use for ThreadSanitizer (whose
    // view of the library's inlined static-guard checks is otherwise incomplete).
    auto warm = client();
    auto health = warm->Get("/health");
    if (!health || health->status != 200) throw Exception(ErrorCode::kUnavailable, "test server did not answer");
  }
  int port() const { return port_; }
  std::string url() const { return "http://127.0.0.1:" + std::to_string(port_); }
  service::Service& service() { return *service_; }
  const std::shared_ptr<service::Service>& service_ptr() { return service_; }
  http::HttpServer& http() { return server_; }

  /// A raw client (its own connection).
  std::unique_ptr<httplib::Client> client(int read_timeout_s = 30) const {
    auto c = std::make_unique<httplib::Client>("127.0.0.1", port_);
    c->set_read_timeout(read_timeout_s, 0);
    c->set_connection_timeout(20, 0);
    c->set_keep_alive(true);
    c->set_tcp_nodelay(true);  // headers and body go out at once (no Nagle / delayed-ACK stall)
    return c;
  }

 private:
  std::shared_ptr<service::Service> service_;
  http::HttpServer server_;
  int port_ = 0;
};

/// What a request got back.
struct Reply {
  int status = 0;
  std::string body;
  std::string content_type;
  std::string server;  // the Server header
};

inline Reply to_reply(const httplib::Result& r) {
  if (!r) {
    ADD_FAILURE() << "no HTTP answer: " << httplib::to_string(r.error());
    return {};
  }
  return {r->status, r->body, r->get_header_value("Content-Type"), r->get_header_value("Server")};
}

inline Reply post(httplib::Client& c, const std::string& path, const std::string& body, const std::string& type,
                  const std::string& accept = "") {
  httplib::Headers h;
  if (!accept.empty()) h.emplace("Accept", accept);
  if (type.empty()) {
    // No Content-Type at all.
    httplib::Request req;
    req.method = "POST";
    req.path = path;
    req.headers = h;
    req.body = body;
    return to_reply(c.send(req));
  }
  return to_reply(c.Post(path, h, body, type));
}

inline Reply get(httplib::Client& c, const std::string& path, const std::string& accept = "") {
  httplib::Headers h;
  if (!accept.empty()) h.emplace("Accept", accept);
  return to_reply(c.Get(path, h));
}

/// The short code of a JSON error body ("" if it is not one).
inline std::string error_code(const Reply& r) {
  const Error e = wire::decode_error_json(r.body, r.status);
  if (r.body.find("\"error\"") == std::string::npos) return "";
  return std::string(to_string(e.code));
}

constexpr const char* kBin = "application/octet-stream";
constexpr const char* kJson = "application/json";

/// Little-endian body builder for hand-made binary bodies.
struct Bytes {
  std::string data;
  Bytes& u32(uint32_t v) {
    for (int i = 0; i < 4; ++i) data.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
    return *this;
  }
  Bytes& f32(float v) { return u32(std::bit_cast<uint32_t>(v)); }
  Bytes& vec(float x, float y, float z) { return f32(x).f32(y).f32(z); }
};

}  // namespace softshell::test
