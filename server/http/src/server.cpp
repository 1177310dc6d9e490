// HttpServer: wiring of cpp-httplib (connection loop, I/O threads, limits), the per-request
// context behind logs and metrics, error pages, lifecycle and the HTTP part of /metrics. The
// routes live in routes_*.cpp, the connection loop in listener.cpp, the I/O threads in
// connection_threads.cpp and the event writer in event_hub.cpp.
#include "softshell/http/server.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

#include "auth.h"
#include "connection_threads.h"
#include "context.h"
#include "extensions.h"
#include "softshell/http/auth.h"
#include "softshell/service/metrics.h"

namespace softshell::http {
namespace {

using Clock = std::chrono::steady_clock;
using internal::Endpoint;
using internal::kEndpointCount;
using service::Histogram;
using service::PrometheusText;

// Per-request context of the connection thread that serves it (cpp-httplib runs a request's
// pre-routing handler, handler and logger on the same thread).
struct RequestContext {
  Clock::time_point start{};
  Endpoint endpoint = Endpoint::kUnmatched;
  bool active = false;
};
thread_local RequestContext t_request;

struct EndpointCounters {
  std::atomic<uint64_t> requests{0}, client_errors{0}, server_errors{0};
  Histogram latency;
  mutable std::mutex status_mu;
  std::map<int, uint64_t> by_status;
};

std::string too_large_message(size_t max_body) {
  return "the request body is larger than this server's limit of " + internal::mib(max_body) + " (--max-body-mb)";
}

// A request body refused before any of it is read: the status and JSON error of the answer.
struct BodyRefusal {
  int status;
  std::string code, message;
};

// Request bodies are framed by Content-Length only. cpp-httplib 0.11 bounds nothing else: it
// buffers a chunked body whole whatever its size, reads a body with neither header until the
// peer closes, and reads a body over its limit through before answering 413. So the framing is
// checked from the headers, before the library reads anything, for the methods whose body it
// reads (POST, PUT, PATCH, DELETE). A DELETE without Content-Length has an empty body (RFC 9112
// section 6.3); `req` is the library's non-const request object, so the header may be added.
std::optional<BodyRefusal> refuse_body(const httplib::Request& req, size_t max_body) {
  const std::string& m = req.method;
  if (m != "POST" && m != "PUT" && m != "PATCH" && m != "DELETE" && m != "PRI") return std::nullopt;
  if (req.has_header("Transfer-Encoding")) {
    return BodyRefusal{411, "length_required",
                       "request bodies with Transfer-Encoding (" + req.get_header_value("Transfer-Encoding").substr(0, 40) +
                           ") are not accepted; send the body with a Content-Length header"};
  }
  const size_t lengths = req.get_header_value_count("Content-Length");
  if (lengths == 0) {
    if (m == "DELETE") {
      const_cast<httplib::Request&>(req).set_header("Content-Length", "0");
      return std::nullopt;
    }
    return BodyRefusal{411, "length_required",
                       "a " + m + " request needs a Content-Length header (the body's size in bytes)"};
  }
  const std::string text = req.get_header_value("Content-Length");
  const bool digits = !text.empty() && text.size() <= 19 && std::all_of(text.begin(), text.end(), [](char c) {
    return c >= '0' && c <= '9';
  });
  if (lengths > 1 || !digits) {
    return BodyRefusal{400, std::string(to_string(ErrorCode::kInvalidArgument)),
                       "the request needs exactly one Content-Length header, a decimal number of bytes"};
  }
  if (std::stoull(text) > max_body) {
    return BodyRefusal{413, std::string(to_string(ErrorCode::kPayloadTooLarge)), too_large_message(max_body)};
  }
  return std::nullopt;
}

// Answers a refused body; the connection ends after the answer, since the body's bytes that
// may follow cannot be parsed as the next request.
void answer_refusal(const BodyRefusal& refusal, httplib::Response& res) {
  res.status = refusal.status;
  res.set_header("Server", internal::kServerHeader);
  res.set_header("Connection", "close");
  res.set_content(wire::encode_error_json(refusal.code, refusal.message), std::string(wire::kJsonMediaType));
  if (internal::Connection* c = internal::current_connection()) c->close_after_answer();
}

}  // namespace

namespace internal {
void set_endpoint(Endpoint endpoint) { t_request.endpoint = endpoint; }
}  // namespace internal

// ---------------------------------------------------------------------------------------------

struct HttpServer::Impl {
  Impl(std::shared_ptr<service::Service> s, ServerOptions o) : ctx(std::move(s), std::move(o)) {
    internal::EventHub::Options events;
    events.keep_alive = ctx.options.event_keep_alive;
    events.stall_timeout = ctx.options.event_stall_timeout;
    const int hardware = static_cast<int>(std::thread::hardware_concurrency());
    events.writers = static_cast<size_t>(ctx.options.event_writers > 0 ? ctx.options.event_writers : std::max(1, hardware / 2));
    ctx.events = std::make_unique<internal::EventHub>(ctx.service, events);
    ctx.metrics = [this] { return metrics_text(); };
    configure();
  }

  void configure() {
    const ServerOptions& options = ctx.options;
    server.new_task_queue = [this] {
      return new internal::ConnectionThreads(static_cast<size_t>(ctx.options.max_connections),
                                             ctx.options.idle_thread_exit, busy, connection_threads);
    };
    server.set_payload_max_length(options.max_body_bytes);
    server.set_keep_alive_max_count(1u << 20);
    server.read_timeout = options.io_timeout;
    server.write_timeout = options.io_timeout;
    server.keep_alive_timeout = options.keep_alive_timeout;
    server.head_timeout = options.head_timeout;
    server.max_head_bytes = std::max<size_t>(options.max_head_bytes, 1024);
    server.max_connections_per_address = options.max_connections_per_address;
    server.set_tcp_nodelay(true);
    // cpp-httplib's default also sets SO_REUSEPORT, which lets a second server bind the same port
    // and silently take half of the connections (and so half of the geometries' clients). Only
    // SO_REUSEADDR (a quick restart over TIME_WAIT connections) is wanted: a busy port is an error.
    server.set_socket_options([](socket_t sock) {
      int yes = 1;
      ::setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    });

    // `Expect: 100-continue` is answered before routing: a body that would be refused gets its
    // answer instead of the 100 (the library would ask for a body of any size).
    server.set_expect_100_continue_handler([this](const httplib::Request& req, httplib::Response& res) {
      t_request = RequestContext{Clock::now(), Endpoint::kUnmatched, true};
      if (internal::Connection* c = internal::current_connection()) c->head_complete();
      if (!internal::authorize(ctx.options.auth_token, req, res)) {
        res.set_header("Server", internal::kServerHeader);
        res.set_header("Content-Length", std::to_string(res.body.size()));
        return res.status;
      }
      const auto refusal = refuse_body(req, ctx.options.max_body_bytes);
      if (!refusal) return 100;
      answer_refusal(*refusal, res);
      // This answer path of the library writes no Content-Length of its own.
      res.set_header("Content-Length", std::to_string(res.body.size()));
      return refusal->status;
    });
    server.set_pre_routing_handler(
        httplib::Server::HandlerWithResponse([this](const httplib::Request& req, httplib::Response& res) {
          t_request = RequestContext{Clock::now(), Endpoint::kUnmatched, true};
          if (internal::Connection* c = internal::current_connection()) c->head_complete();
          res.set_header("Server", internal::kServerHeader);  // kept by every handler and error page
          // The token first: a client without it learns no limit of this server.
          if (!internal::authorize(ctx.options.auth_token, req, res)) return httplib::Server::HandlerResponse::Handled;
          if (const auto refusal = refuse_body(req, ctx.options.max_body_bytes)) {
            answer_refusal(*refusal, res);
            return httplib::Server::HandlerResponse::Handled;
          }
          // cpp-httplib inflates compressed request bodies without bounding the inflated size
          // (--max-body-mb limits only the compressed bytes): a small gzip bomb could take all
          // memory. Compressed bodies are refused before they are read; the connection is closed
          // because its unread body cannot be skipped.
          const std::string encoding = req.get_header_value("Content-Encoding");
          if (!encoding.empty() && encoding != "identity") {
            internal::set_error(res, Error{ErrorCode::kUnsupportedMediaType,
                                           "compressed request bodies (Content-Encoding: " + encoding.substr(0, 40) +
                                               ") are not accepted; send the body uncompressed"});
            res.set_header("Connection", "close");
            if (internal::Connection* c = internal::current_connection()) c->close_after_answer();
            return httplib::Server::HandlerResponse::Handled;
          }
          return httplib::Server::HandlerResponse::Unhandled;
        }));
    server.set_error_handler(httplib::Server::HandlerWithResponse(
        [this](const httplib::Request& req, httplib::Response& res) { return error_page(req, res); }));
    server.set_exception_handler([this](const httplib::Request&, httplib::Response& res, std::exception_ptr ep) {
      internal::set_error(res, internal::describe(ep));
    });
    server.set_logger([this](const httplib::Request& req, const httplib::Response& res) { finished(req, res); });

    internal::add_service_routes(router, ctx);
    internal::add_geometry_routes(router, ctx);
    internal::add_result_routes(router, ctx);
    internal::add_hold_routes(router, ctx);
    internal::add_event_routes(router, ctx);
    internal::add_browser_routes(router, ctx);
    internal::install_cors(server, ctx.options.cors_origins);
  }

  // Errors cpp-httplib produces itself (no route, body too large, malformed request) get the
  // JSON error layout too. Errors our handlers set already have a body.
  httplib::Server::HandlerResponse error_page(const httplib::Request& req, httplib::Response& res) {
    if (!res.body.empty()) return httplib::Server::HandlerResponse::Unhandled;
    std::string code, message;
    switch (res.status) {
      case 404: {
        const std::string allowed = router.allowed_methods(req.path);
        if (!allowed.empty()) {
          res.status = 405;
          res.set_header("Allow", allowed);
          code = "method_not_allowed";
          message = req.method + " is not allowed on " + req.path + " (allowed: " + allowed + ")";
        } else {
          code = std::string(to_string(ErrorCode::kNotFound));
          message = "no endpoint " + req.method + " " + req.path + " (see PROTOCOL.md)";
        }
        break;
      }
      case 413:
        code = std::string(to_string(ErrorCode::kPayloadTooLarge));
        message = too_large_message(ctx.options.max_body_bytes);
        break;
      case 414:
        code = "uri_too_long";
        message = "the request URI is too long";
        break;
      default:
        code = res.status < 500 ? std::string(to_string(ErrorCode::kInvalidArgument))
                                : std::string(to_string(ErrorCode::kInternal));
        message = res.status < 500 ? "malformed HTTP request (status " + std::to_string(res.status) + ")"
                                   : "internal error (status " + std::to_string(res.status) + ")";
    }
    res.set_content(wire::encode_error_json(code, message), std::string(wire::kJsonMediaType));
    return httplib::Server::HandlerResponse::Handled;
  }

  // One log line and the metrics of every finished request.
  void finished(const httplib::Request& req, const httplib::Response& res) {
    const bool timed = t_request.active;
    const double seconds = timed ? std::chrono::duration<double>(Clock::now() - t_request.start).count() : 0.0;
    const Endpoint endpoint = timed ? t_request.endpoint : Endpoint::kUnmatched;
    t_request.active = false;
    auto& c = counters[static_cast<size_t>(endpoint)];
    c.requests.fetch_add(1, std::memory_order_relaxed);
    if (res.status >= 400 && res.status < 500) c.client_errors.fetch_add(1, std::memory_order_relaxed);
    if (res.status >= 500) c.server_errors.fetch_add(1, std::memory_order_relaxed);
    c.latency.observe(seconds);
    {
      std::lock_guard lock(c.status_mu);
      ++c.by_status[res.status];
    }
    const service::Logger& logger = ctx.options.logger;
    if (logger.enabled(service::LogLevel::kInfo)) {
      logger.info(req.method + " " + req.path + " " + std::to_string(res.status) + " " +
                  std::to_string(static_cast<long long>(seconds * 1e6)) + "us");
    }
  }

  // The HTTP layer's families, then the service's.
  std::string metrics_text() const {
    PrometheusText m;
    m.family("softshell_http_requests_total", "counter", "HTTP requests answered, by endpoint and status.");
    for (size_t e = 0; e < counters.size(); ++e) {
      const auto& c = counters[e];
      const std::string endpoint = PrometheusText::label("endpoint", internal::endpoint_name(static_cast<Endpoint>(e)));
      std::lock_guard lock(c.status_mu);
      for (const auto& [status, n] : c.by_status) {
        m.sample("softshell_http_requests_total", endpoint + "," + PrometheusText::label("status", std::to_string(status)),
                 static_cast<double>(n));
      }
    }
    m.family("softshell_http_request_duration_seconds", "histogram",
             "Time from a request's headers to its response (for event streams: to the hand-off), by endpoint.");
    for (size_t e = 0; e < counters.size(); ++e) {
      const auto snap = counters[e].latency.snapshot();
      if (snap.count == 0) continue;
      m.histogram("softshell_http_request_duration_seconds",
                  PrometheusText::label("endpoint", internal::endpoint_name(static_cast<Endpoint>(e))), snap);
    }
    auto gauge = [&](const char* name, const char* help, double v) {
      m.family(name, "gauge", help);
      m.sample(name, "", v);
    };
    auto counter = [&](const char* name, const char* help, double v) {
      m.family(name, "counter", help);
      m.sample(name, "", v);
    };
    gauge("softshell_http_connections_busy", "Connections being served (one I/O thread each).", busy.load());
    gauge("softshell_http_connection_threads", "I/O threads alive (busy or idle).", connection_threads.load());
    gauge("softshell_http_long_polls_waiting", "latest_result requests waiting for a newer result.",
          ctx.long_polls.load());
    const auto ev = ctx.events->stats();
    gauge("softshell_http_event_streams", "Event streams open (served by the event writer, no I/O thread each).",
          static_cast<double>(ev.streams));
    gauge("softshell_http_event_topics", "Geometries with open event streams.", static_cast<double>(ev.topics));
    counter("softshell_http_event_frames_serialized_total", "Results serialized for event streams (once per result).",
            static_cast<double>(ev.frames_serialized));
    counter("softshell_http_event_frames_sent_total", "Result events written out completely, over all streams.",
            static_cast<double>(ev.frames_sent));
    counter("softshell_http_event_frames_replaced_total",
            "Result events a slow stream skipped because a newer one replaced them (latest wins).",
            static_cast<double>(ev.frames_replaced));
    counter("softshell_http_event_streams_stalled_total", "Event streams closed because their client took nothing.",
            static_cast<double>(ev.streams_stalled));
    m.family("softshell_http_event_delivery_seconds", "histogram",
             "From a stored result reaching the event writers to its event written to a stream's socket, per stream.");
    m.histogram("softshell_http_event_delivery_seconds", "", ev.delivery);
    return m.take() + ctx.service->metrics_text();
  }

  internal::Listener server;
  internal::Context ctx;
  internal::Router router{server};

  std::mutex lifecycle_mu;
  std::thread thread;
  std::atomic<int> port{0};
  std::atomic<bool> started{false}, stopped{false};

  std::atomic<int> busy{0}, connection_threads{0};
  std::array<EndpointCounters, kEndpointCount> counters;
};

HttpServer::HttpServer(std::shared_ptr<service::Service> service, ServerOptions options)
    : impl_(std::make_unique<Impl>(std::move(service), std::move(options))) {}

HttpServer::~HttpServer() {
  stop();
  impl_->ctx.events->stop();  // also when never started
}

Result<int> HttpServer::start(const std::string& host, int port) {
  std::lock_guard lock(impl_->lifecycle_mu);
  if (impl_->started.load()) return Error{ErrorCode::kUnavailable, "the HTTP server was started already"};
  if (port < 0 || port > 65535) return Error{ErrorCode::kInvalidArgument, "port must be 0..65535"};
  if (const std::string& token = impl_->ctx.options.auth_token; !token.empty()) {
    if (auto ok = check_auth_token(token); !ok) return Error{ErrorCode::kInvalidArgument, "auth_token: " + ok.error().message};
  }
  int bound = -1;
  if (port == 0) {
    bound = impl_->server.bind_to_any_port(host);
  } else if (impl_->server.bind_to_port(host, port)) {
    bound = port;
  }
  if (bound <= 0) {
    return Error{ErrorCode::kUnavailable,
                 "cannot listen on " + host + ":" + std::to_string(port) + " (address in use or not available)"};
  }
  impl_->port.store(bound);
  impl_->server.raise_backlog(std::max(impl_->ctx.options.max_connections, 4096));
  impl_->thread = std::thread([this] { impl_->server.listen_after_bind(); });
  // stop() only works once the accept loop runs.
  const auto deadline = Clock::now() + std::chrono::seconds(10);
  while (!impl_->server.is_running() && Clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  impl_->started.store(true);
  return bound;
}

void HttpServer::stop() {
  std::lock_guard lock(impl_->lifecycle_mu);
  if (!impl_->started.load() || impl_->stopped.load()) return;
  impl_->stopped.store(true);
  impl_->ctx.stop.request_stop();  // releases long polls and waiting deformation and hold requests
  impl_->ctx.events->stop();       // ends every event stream after the event it is writing
  impl_->server.wake_connections();
  impl_->server.stop();
  if (impl_->thread.joinable()) impl_->thread.join();
}

int HttpServer::port() const { return impl_->port.load(); }
bool HttpServer::running() const { return impl_->started.load() && !impl_->stopped.load(); }
std::string HttpServer::metrics_text() const { return impl_->metrics_text(); }
int HttpServer::busy_connections() const { return impl_->busy.load(); }
int HttpServer::connection_threads() const { return impl_->connection_threads.load(); }
int HttpServer::waiting_long_polls() const { return impl_->ctx.long_polls.load(); }
int HttpServer::event_streams() const { return static_cast<int>(impl_->ctx.events->stats().streams); }
const ServerOptions& HttpServer::options() const { return impl_->ctx.options; }
service::Service& HttpServer::service() const { return *impl_->ctx.service; }

std::vector<EndpointStats> HttpServer::endpoint_stats() const {
  std::vector<EndpointStats> out;
  for (size_t e = 0; e < impl_->counters.size(); ++e) {
    const auto& c = impl_->counters[e];
    out.push_back({std::string(internal::endpoint_name(static_cast<Endpoint>(e))), c.requests.load(),
                   c.client_errors.load(), c.server_errors.load()});
  }
  return out;
}

}  // namespace softshell::http
