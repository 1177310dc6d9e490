#include "softshell/http/server.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <map>
#include <regex>
#include <mutex>
#include <stop_token>
#include <thread>

#include <httplib.h>

#include "extensions.h"
#include "softshell/http/negotiation.h"
#include "softshell/service/metrics.h"
#include "softshell/wire.h"

namespace softshell::http {
namespace {

using Clock = std::chrono::steady_clock;
using service::Histogram;
using service::PrometheusText;

// ---------------------------------------------------------------------------------------------
// Endpoints: labels for logs and metrics.

enum class Endpoint : int {
  kHealth,
  kMetrics,
  kUpload,
  kList,
  kGeometry,
  kStatus,
  kDeform,
  kResultIds,
  kResult,
  kResultRequest,
  kLatest,
  kLimitComb,
  kRender,
  kStresses,
  kApp,
  kUnmatched,
  kCount
};

constexpr std::array<std::string_view, static_cast<size_t>(Endpoint::kCount)> kEndpointNames = {
    "GET /health",
    "GET /metrics",
    "POST /geometries",
    "GET /geometries",
    "GET /geometries/{id}",
    "GET /geometries/{id}/status",
    "POST /geometries/{id}/results",
    "GET /geometries/{id}/results",
    "GET /geometries/{id}/results/{res_id}",
    "GET /geometries/{id}/results/{res_id}/request",
    "GET /geometries/{id}/latest_result",
    "GET /geometries/{id}/limit_comb",
    "GET /geometries/{id}/render",
    "GET|POST /geometries/{id}/results/{res_id}/stresses",
    "GET /, /app/{file}",
    "unmatched",
};

// Per-request context of the connection thread that serves it (cpp-httplib runs a request's
// pre-routing handler, handler and logger on the same thread).
struct RequestContext {
  Clock::time_point start{};
  Endpoint endpoint = Endpoint::kUnmatched;
  bool active = false;
};
thread_local RequestContext t_request;

// ---------------------------------------------------------------------------------------------
// Connection threads: one per open connection, created on demand up to a maximum and kept for
// reuse; a thread idle for `idle_exit` exits (down to kKeep threads), so a burst of clients does not
// leave hundreds of idle threads behind.

class ConnectionThreads final : public httplib::TaskQueue {
 public:
  static constexpr size_t kKeep = 8;

  ConnectionThreads(size_t max_threads, std::chrono::milliseconds idle_exit, std::atomic<int>& busy,
                    std::atomic<int>& live)
      : max_(std::max<size_t>(1, max_threads)), idle_exit_(idle_exit), busy_(busy), live_count_(live) {}
  ~ConnectionThreads() override { shutdown(); }

  void enqueue(std::function<void()> fn) override {
    std::lock_guard lock(mu_);
    reap_locked();
    jobs_.push_back(std::move(fn));
    // Every idle thread takes one job; jobs beyond them get a new thread while allowed.
    if (jobs_.size() > idle_ && live_ < max_) {
      ++live_;
      live_count_.store(static_cast<int>(live_));
      threads_.emplace_back([this] { work(); });
    } else {
      cv_.notify_one();
    }
  }

  void shutdown() override {
    std::vector<std::thread> threads;
    {
      std::lock_guard lock(mu_);
      stopping_ = true;
      threads.swap(threads_);
      exited_.clear();
    }
    cv_.notify_all();
    for (auto& t : threads) t.join();
  }

 private:
  void work() {
    std::unique_lock lock(mu_);
    for (;;) {
      ++idle_;
      const bool woken = cv_.wait_for(lock, idle_exit_, [&] { return stopping_ || !jobs_.empty(); });
      --idle_;
      if (!woken && live_ > kKeep) {  // idle for long: leave (joined by a later enqueue)
        --live_;
        live_count_.store(static_cast<int>(live_));
        exited_.push_back(std::this_thread::get_id());
        return;
      }
      if (jobs_.empty()) {
        if (stopping_) return;
        continue;
      }
      auto fn = std::move(jobs_.front());
      jobs_.pop_front();
      lock.unlock();
      busy_.fetch_add(1);
      fn();
      busy_.fetch_sub(1);
      lock.lock();
    }
  }

  // Joins threads that left for idleness (they gave up the lock for good before their id became
  // visible here, so these joins return at once).
  void reap_locked() {
    for (const auto id : exited_) {
      auto it = std::find_if(threads_.begin(), threads_.end(), [&](const std::thread& t) { return t.get_id() == id; });
      if (it != threads_.end()) {
        it->join();
        threads_.erase(it);
      }
    }
    exited_.clear();
  }

  const size_t max_;
  const std::chrono::milliseconds idle_exit_;
  std::atomic<int>& busy_;
  std::atomic<int>& live_count_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> jobs_;
  std::vector<std::thread> threads_;     // every thread not joined yet
  std::vector<std::thread::id> exited_;  // threads that left for idleness, to join
  size_t live_ = 0;                      // threads running work()
  size_t idle_ = 0;
  bool stopping_ = false;
};

// cpp-httplib 0.11 listens with a backlog of 5: a burst of clients (hundreds of long polls
// connecting at once) overflows it and the dropped SYNs cost the clients a second or more.
// Calling listen() again on the bound socket raises the backlog (Linux updates it in place).
class Listener final : public httplib::Server {
 public:
  void raise_backlog(int backlog) {
    const auto sock = svr_sock_.load();
    if (sock != INVALID_SOCKET) ::listen(sock, backlog);
  }
};

// ---------------------------------------------------------------------------------------------
// Helpers

template <class T>
T value_or_throw(Result<T> r) {
  if (!r) throw Exception(r.error());
  return std::move(r).value();
}

GeomId parse_id(std::string_view text) { return value_or_throw(GeomId::from_hex(text)); }

void set_error(httplib::Response& res, const Error& error) {
  res.status = wire::http_status(error.code);
  res.set_content(wire::encode_error_json(error), std::string(wire::kJsonMediaType));
}

std::string mib(size_t bytes) {
  const double m = static_cast<double>(bytes) / (1024.0 * 1024.0);
  char buf[32];
  std::snprintf(buf, sizeof buf, m < 10 ? "%.2f MiB" : "%.0f MiB", m);
  return buf;
}

// Bounds the bytes of JSON bodies decoded at once (their DOM takes many times their size).
class JsonGate {
 public:
  explicit JsonGate(size_t budget) : budget_(budget) {}
  bool enter(size_t bytes) {
    size_t used = used_.load();
    do {
      if (bytes > budget_ || used > budget_ - bytes) return false;
    } while (!used_.compare_exchange_weak(used, used + bytes));
    return true;
  }
  void leave(size_t bytes) { used_.fetch_sub(bytes); }

 private:
  const size_t budget_;
  std::atomic<size_t> used_{0};
};

struct EndpointCounters {
  std::atomic<uint64_t> requests{0}, client_errors{0}, server_errors{0};
  Histogram latency;
  mutable std::mutex status_mu;
  std::map<int, uint64_t> by_status;
};

}  // namespace

// ---------------------------------------------------------------------------------------------

struct HttpServer::Impl {
  Impl(std::shared_ptr<service::Service> s, ServerOptions o)
      : service(std::move(s)),
        options(std::move(o)),
        json_gate(options.max_json_decode_bytes ? options.max_json_decode_bytes : 4 * options.max_body_bytes) {
    configure();
  }

  // --- wiring --------------------------------------------------------------------------------
  void configure() {
    server.new_task_queue = [this] {
      return new ConnectionThreads(static_cast<size_t>(options.max_connections), options.idle_thread_exit, busy,
                                   connection_threads);
    };
    server.set_payload_max_length(options.max_body_bytes);
    server.set_keep_alive_max_count(1u << 20);
    server.set_keep_alive_timeout(options.keep_alive_timeout.count());
    server.set_read_timeout(options.io_timeout.count());
    server.set_write_timeout(options.io_timeout.count());
    server.set_tcp_nodelay(true);
    // cpp-httplib's default also sets SO_REUSEPORT, which lets a second server bind the same port
    // and silently take half of the connections (and so half of the geometries' clients). Only
    // SO_REUSEADDR (a quick restart over TIME_WAIT connections) is wanted: a busy port is an error.
    server.set_socket_options([](socket_t sock) {
      int yes = 1;
      ::setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    });

    server.set_pre_routing_handler(
        httplib::Server::HandlerWithResponse([](const httplib::Request& req, httplib::Response& res) {
          t_request = RequestContext{Clock::now(), Endpoint::kUnmatched, true};
          // cpp-httplib inflates compressed request bodies without bounding the inflated size
          // (--max-body-mb limits only the compressed bytes): a small gzip bomb could take all
          // memory. Compressed bodies are refused before they are read; the connection is closed
          // because its unread body cannot be skipped.
          const std::string encoding = req.get_header_value("Content-Encoding");
          if (!encoding.empty() && encoding != "identity") {
            set_error(res, Error{ErrorCode::kUnsupportedMediaType,
                                 "compressed request bodies (Content-Encoding: " + encoding.substr(0, 40) +
                                     ") are not accepted; send the body uncompressed"});
            res.set_header("Connection", "close");
            return httplib::Server::HandlerResponse::Handled;
          }
          return httplib::Server::HandlerResponse::Unhandled;
        }));
    server.set_error_handler(httplib::Server::HandlerWithResponse(
        [this](const httplib::Request& req, httplib::Response& res) { return error_page(req, res); }));
    server.set_exception_handler([this](const httplib::Request&, httplib::Response& res, std::exception_ptr ep) {
      set_error(res, describe(ep));
    });
    server.set_logger([this](const httplib::Request& req, const httplib::Response& res) { finished(req, res); });

    using Req = const httplib::Request&;
    using Res = httplib::Response&;
    get(R"(/health)", Endpoint::kHealth, [this](Req, Res res) { health(res); });
    get(R"(/metrics)", Endpoint::kMetrics, [this](Req, Res res) {
      res.set_content(metrics_text(), "text/plain; version=0.0.4; charset=utf-8");
    });
    post(R"(/geometries)", Endpoint::kUpload, [this](Req req, Res res) { upload(req, res); });
    get(R"(/geometries)", Endpoint::kList, [this](Req, Res res) {
      res.set_content(wire::encode_geometry_list_json(service->geometries()), std::string(wire::kJsonMediaType));
    });
    get(R"(/geometries/([^/]+))", Endpoint::kGeometry, [this](Req req, Res res) { geometry(req, res); });
    get(R"(/geometries/([^/]+)/status)", Endpoint::kStatus, [this](Req req, Res res) {
      const auto info = value_or_throw(service->info(parse_id(req.matches[1].str())));
      res.set_content(wire::encode_geometry_info_json(info), std::string(wire::kJsonMediaType));
    });
    post(R"(/geometries/([^/]+)/results)", Endpoint::kDeform, [this](Req req, Res res) { deform(req, res); });
    get(R"(/geometries/([^/]+)/results)", Endpoint::kResultIds, [this](Req req, Res res) {
      const auto ids = value_or_throw(service->result_ids(parse_id(req.matches[1].str())));
      res.set_content(wire::encode_result_ids_json(ids), std::string(wire::kJsonMediaType));
    });
    get(R"(/geometries/([^/]+)/results/([^/]+))", Endpoint::kResult, [this](Req req, Res res) {
      const GeomId id = parse_id(req.matches[1].str());
      const uint32_t k = value_or_throw(parse_u32(req.matches[2].str(), "res_id"));
      write_result(req, res, *value_or_throw(service->result(id, k)), wire::Format::kJson);
    });
    get(R"(/geometries/([^/]+)/results/([^/]+)/request)", Endpoint::kResultRequest, [this](Req req, Res res) {
      const GeomId id = parse_id(req.matches[1].str());
      const uint32_t k = value_or_throw(parse_u32(req.matches[2].str(), "res_id"));
      const auto stored = value_or_throw(service->result(id, k));
      res.set_content(wire::encode_request_json(stored->request), std::string(wire::kJsonMediaType));
    });
    get(R"(/geometries/([^/]+)/latest_result)", Endpoint::kLatest, [this](Req req, Res res) { latest(req, res); });
    get(R"(/geometries/([^/]+)/limit_comb)", Endpoint::kLimitComb, [this](Req req, Res res) { limit_comb(req, res); });
    // The browser client's extensions (extensions.h).
    get(R"(/geometries/([^/]+)/render)", Endpoint::kRender, [this](Req req, Res res) { internal::render_route(*service, req, res); });
    get(R"(/geometries/([^/]+)/results/([^/]+)/stresses)", Endpoint::kStresses, [this](Req req, Res res) { internal::stresses_route(*service, req, res); });
    post(R"(/geometries/([^/]+)/results/([^/]+)/stresses)", Endpoint::kStresses, [this](Req req, Res res) { internal::stresses_route(*service, req, res); });
    get(R"(/|/index\.html|/app/[A-Za-z0-9._-]+)", Endpoint::kApp, [this](Req req, Res res) {
      if (!internal::app_route(req, res)) throw Exception(ErrorCode::kNotFound, "no file " + req.path + " in the web app");
    });
    internal::install_cors(server, options.cors_origins);
  }

  template <class Fn>
  httplib::Server::Handler wrap(Endpoint endpoint, Fn fn) {
    return [this, endpoint, fn](const httplib::Request& req, httplib::Response& res) {
      t_request.endpoint = endpoint;
      try {
        fn(req, res);
      } catch (...) {
        set_error(res, describe(std::current_exception()));
      }
    };
  }
  template <class Fn>
  void get(const char* pattern, Endpoint e, Fn fn) {
    server.Get(pattern, wrap(e, fn));
    routes.emplace_back(std::regex(pattern), "GET");
  }
  template <class Fn>
  void post(const char* pattern, Endpoint e, Fn fn) {
    server.Post(pattern, wrap(e, fn));
    routes.emplace_back(std::regex(pattern), "POST");
  }

  // An exception from a handler as the error to answer with (bugs go to the SDK log sink).
  static Error describe(std::exception_ptr ep) { return error_from(std::move(ep), "handling this request"); }

  // Errors cpp-httplib produces itself (no route, body too large, malformed request) get the
  // JSON error layout too. Errors our handlers set already have a body.
  httplib::Server::HandlerResponse error_page(const httplib::Request& req, httplib::Response& res) {
    if (!res.body.empty()) return httplib::Server::HandlerResponse::Unhandled;
    std::string code, message;
    switch (res.status) {
      case 404: {
        std::string allowed;
        for (const auto& [pattern, method] : routes) {
          if (std::regex_match(req.path, pattern) && allowed.find(method) == std::string::npos) {
            allowed += (allowed.empty() ? "" : ", ") + method;
          }
        }
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
        message = "the request body is larger than this server's limit of " + mib(options.max_body_bytes) +
                  " (--max-body-mb)";
        break;
      case 414:
        code = "uri_too_long";
        message = "the request URI is too long";
        break;
      default:
        code = res.status < 500 ? std::string(to_string(ErrorCode::kInvalidArgument)) : std::string(to_string(ErrorCode::kInternal));
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
    if (options.logger.enabled(service::LogLevel::kInfo)) {
      options.logger.info(req.method + " " + req.path + " " + std::to_string(res.status) + " " +
                          std::to_string(static_cast<long long>(seconds * 1e6)) + "us");
    }
  }

  // --- request parsing -----------------------------------------------------------------------
  static wire::Format body_format_of(const httplib::Request& req) {
    return value_or_throw(body_format(req.get_header_value("Content-Type")));
  }
  static wire::Format reply_format(const httplib::Request& req, wire::Format fallback) {
    return response_format(req.get_header_value("Accept"), fallback);
  }

  template <class T>
  T decode(const httplib::Request& req, wire::Format format, Result<T> (*binary)(std::string_view),
           Result<T> (*json)(std::string_view)) {
    if (format == wire::Format::kBinary) return value_or_throw(binary(req.body));
    const size_t bytes = req.body.size();
    if (!json_gate.enter(bytes)) {
      throw Exception(ErrorCode::kResourceExhausted,
                      "the server is decoding other large JSON bodies right now; retry shortly or send the binary "
                      "format");
    }
    struct Leave {
      JsonGate& gate;
      size_t bytes;
      ~Leave() { gate.leave(bytes); }
    } leave{json_gate, bytes};
    return value_or_throw(json(req.body));
  }

  // --- handlers ------------------------------------------------------------------------------
  void health(httplib::Response& res) {
    if (service->shutting_down() || stop_source.stop_requested()) {
      set_error(res, Error{ErrorCode::kUnavailable, "the server is shutting down"});
      return;
    }
    res.set_content(R"({"status":"ok"})", std::string(wire::kJsonMediaType));
  }

  void upload(const httplib::Request& req, httplib::Response& res) {
    const wire::Format format = body_format_of(req);
    Geometry g = decode<Geometry>(req, format, &wire::decode_geometry_binary, &wire::decode_geometry_json);
    const std::string ns = req.has_param("namespace") ? req.get_param_value("namespace") : std::string();
    const UploadResult up = value_or_throw(service->upload(std::move(g.mesh), g.material, ns));
    res.status = up.created ? 201 : 200;
    if (reply_format(req, format) == wire::Format::kBinary) {
      res.set_content(wire::encode_upload_response_binary(up.id), std::string(wire::kBinaryMediaType));
    } else {
      res.set_content(wire::encode_upload_response_json(up.id, up.status), std::string(wire::kJsonMediaType));
    }
  }

  void geometry(const httplib::Request& req, httplib::Response& res) {
    const GeomId id = parse_id(req.matches[1].str());
    const auto g = value_or_throw(service->geometry(id));
    if (reply_format(req, wire::Format::kJson) == wire::Format::kBinary) {
      if (!wire::geometry_fits_binary(g->mesh)) {
        throw Exception(ErrorCode::kNotAcceptable,
                        "geometry " + id.hex() +
                            " has no binary layout (it has faces that are not quads, crease or corner tags, or "
                            "boundary \"none\"); ask for application/json");
      }
      auto body = wire::encode_geometry_binary(g->mesh, g->material);
      if (!body) throw Exception(ErrorCode::kNotAcceptable, body.error().message);
      res.set_content(std::move(*body), std::string(wire::kBinaryMediaType));
    } else {
      res.set_content(wire::encode_geometry_json(g->mesh, g->material, id, g->name_space),
                      std::string(wire::kJsonMediaType));
    }
  }

  void deform(const httplib::Request& req, httplib::Response& res) {
    const GeomId id = parse_id(req.matches[1].str());
    value_or_throw(service->info(id));  // 404 before anything else
    const wire::Format format = body_format_of(req);
    DeformationRequest request =
        decode<DeformationRequest>(req, format, &wire::decode_request_binary, &wire::decode_request_json);
    auto future = service->deform(id, std::move(request));
    // The solve runs on a service worker; this connection thread only waits for it.
    const auto stop = stop_source.get_token();
    while (future.wait_for(std::chrono::milliseconds(50)) != std::future_status::ready) {
      if (stop.stop_requested()) {
        throw Exception(ErrorCode::kUnavailable,
                        "the server is shutting down; the deformation may still be stored (see GET "
                        "/geometries/{id}/results)");
      }
    }
    const auto stored = value_or_throw(future.get());
    write_result(req, res, *stored, format);
  }

  void write_result(const httplib::Request& req, httplib::Response& res, const service::StoredResult& stored,
                    wire::Format fallback) {
    const DeformationResult result = stored.to_result();
    if (reply_format(req, fallback) == wire::Format::kBinary) {
      auto body = wire::encode_result_binary(result);
      if (!body) {
        throw Exception(ErrorCode::kNotAcceptable, "result " + std::to_string(stored.res_id) +
                                                       " is stored but has no binary form: " + body.error().message);
      }
      res.set_content(std::move(*body), std::string(wire::kBinaryMediaType));
    } else {
      res.set_content(wire::encode_result_json(result), std::string(wire::kJsonMediaType));
    }
  }

  void latest(const httplib::Request& req, httplib::Response& res) {
    const GeomId id = parse_id(req.matches[1].str());
    const uint32_t have = req.has_param("have") ? value_or_throw(parse_u32(req.get_param_value("have"), "have")) : 0;
    double wait = options.default_wait_seconds;
    if (req.has_param("wait")) {
      wait = value_or_throw(parse_number(req.get_param_value("wait"), "wait"));
      if (wait < 0) throw Exception(ErrorCode::kInvalidArgument, "'wait' must be >= 0 seconds");
    }
    wait = std::min(wait, options.max_wait_seconds);
    // A long poll holds this connection's thread: bound how many may do so at once.
    struct Slot {
      std::atomic<int>& count;
      bool held = false;
      ~Slot() {
        if (held) count.fetch_sub(1);
      }
    } slot{long_polls};
    if (wait > 0) {
      const int limit = std::max(1, options.max_connections - options.reserved_connections);
      if (long_polls.fetch_add(1) >= limit) {
        long_polls.fetch_sub(1);
        res.set_header("Retry-After", "1");
        throw Exception(ErrorCode::kUnavailable,
                        "too many clients are waiting for results right now (" + std::to_string(limit) +
                            "); retry in a second");
      }
      slot.held = true;
    }
    const auto ms = std::chrono::milliseconds(static_cast<int64_t>(wait * 1000.0));
    const auto stored = value_or_throw(service->latest_result(id, have, ms, stop_source.get_token()));
    if (!stored) {
      res.status = 204;
      return;
    }
    write_result(req, res, *stored, wire::Format::kJson);
  }

  void limit_comb(const httplib::Request& req, httplib::Response& res) {
    const GeomId id = parse_id(req.matches[1].str());
    auto required = [&](const char* name) {
      if (!req.has_param(name)) {
        throw Exception(ErrorCode::kInvalidArgument,
                        std::string("limit_comb needs the query parameter '") + name + "' (u, v, face-index)");
      }
      return req.get_param_value(name);
    };
    SurfacePoint p;
    p.u = value_or_throw(parse_number(required("u"), "u"));
    p.v = value_or_throw(parse_number(required("v"), "v"));
    const uint32_t face = value_or_throw(parse_u32(required("face-index"), "face-index"));
    const uint32_t subface = req.has_param("subface") ? value_or_throw(parse_u32(req.get_param_value("subface"), "subface")) : 0;
    if (face > static_cast<uint32_t>(std::numeric_limits<int32_t>::max()) ||
        subface > static_cast<uint32_t>(std::numeric_limits<int32_t>::max())) {
      throw Exception(ErrorCode::kInvalidArgument, "face-index or subface out of range");
    }
    p.face = static_cast<int32_t>(face);
    p.subface = static_cast<int32_t>(subface);
    const LimitComb comb = value_or_throw(service->limit_comb(id, p));
    if (reply_format(req, wire::Format::kJson) == wire::Format::kBinary) {
      auto body = wire::encode_limit_comb_binary(comb);
      if (!body) throw Exception(ErrorCode::kNotAcceptable, body.error().message);
      res.set_content(std::move(*body), std::string(wire::kBinaryMediaType));
    } else {
      res.set_content(wire::encode_limit_comb_json(comb), std::string(wire::kJsonMediaType));
    }
  }

  // --- metrics -------------------------------------------------------------------------------
  std::string metrics_text() const {
    PrometheusText m;
    m.family("softshell_http_requests_total", "counter", "HTTP requests answered, by endpoint and status.");
    for (size_t e = 0; e < counters.size(); ++e) {
      const auto& c = counters[e];
      std::lock_guard lock(c.status_mu);
      for (const auto& [status, n] : c.by_status) {
        m.sample("softshell_http_requests_total",
                 PrometheusText::label("endpoint", kEndpointNames[e]) + "," +
                     PrometheusText::label("status", std::to_string(status)),
                 static_cast<double>(n));
      }
    }
    m.family("softshell_http_request_duration_seconds", "histogram",
             "Time from a request's headers to its response, by endpoint.");
    for (size_t e = 0; e < counters.size(); ++e) {
      const auto snap = counters[e].latency.snapshot();
      if (snap.count == 0) continue;
      m.histogram("softshell_http_request_duration_seconds", PrometheusText::label("endpoint", kEndpointNames[e]), snap);
    }
    m.family("softshell_http_connections_busy", "gauge", "Connections being served (one I/O thread each).");
    m.sample("softshell_http_connections_busy", "", busy.load());
    m.family("softshell_http_connection_threads", "gauge", "I/O threads alive (busy or idle).");
    m.sample("softshell_http_connection_threads", "", connection_threads.load());
    m.family("softshell_http_long_polls_waiting", "gauge", "latest_result requests waiting for a newer result.");
    m.sample("softshell_http_long_polls_waiting", "", long_polls.load());

    const service::ServiceStats s = service->stats();
    m.family("softshell_geometries", "gauge", "Stored geometries by precomputation status.");
    m.sample("softshell_geometries", PrometheusText::label("status", "precomputing"), static_cast<double>(s.geometries_precomputing));
    m.sample("softshell_geometries", PrometheusText::label("status", "ready"), static_cast<double>(s.geometries_ready));
    m.sample("softshell_geometries", PrometheusText::label("status", "failed"), static_cast<double>(s.geometries_failed));
    m.family("softshell_results", "gauge", "Stored results over all geometries.");
    m.sample("softshell_results", "", static_cast<double>(s.results));
    m.family("softshell_precomputations_running", "gauge", "Precomputations executing now.");
    m.sample("softshell_precomputations_running", "", s.precomputations_running);
    m.family("softshell_pending_solves", "gauge", "Deformation requests waiting for a precomputation.");
    m.sample("softshell_pending_solves", "", static_cast<double>(s.pending_solves));
    m.family("softshell_factor_cache_bytes", "gauge", "Memory held by cached factorizations.");
    m.sample("softshell_factor_cache_bytes", "", static_cast<double>(s.cache.bytes));
    m.family("softshell_factor_cache_budget_bytes", "gauge", "Factor cache budget (--cache-mb).");
    m.sample("softshell_factor_cache_budget_bytes", "", static_cast<double>(s.cache.budget));
    m.family("softshell_factor_cache_entries", "gauge", "Cached factorizations.");
    m.sample("softshell_factor_cache_entries", "", static_cast<double>(s.cache.entries));
    m.family("softshell_factor_cache_events_total", "counter", "Factor cache hits, misses and evictions.");
    m.sample("softshell_factor_cache_events_total", PrometheusText::label("event", "hit"), static_cast<double>(s.cache.hits));
    m.sample("softshell_factor_cache_events_total", PrometheusText::label("event", "miss"), static_cast<double>(s.cache.misses));
    m.sample("softshell_factor_cache_events_total", PrometheusText::label("event", "eviction"), static_cast<double>(s.cache.evictions));
    m.family("softshell_store_bytes", "gauge", "Memory held for meshes, precomputed models and results.");
    m.sample("softshell_store_bytes", "", static_cast<double>(s.store_bytes));
    m.family("softshell_store_budget_bytes", "gauge", "Budget of the store (--store-mb).");
    m.sample("softshell_store_budget_bytes", "", static_cast<double>(s.store_budget));
    m.family("softshell_refused_no_memory_total", "counter", "Uploads and results refused by the store budget (507).");
    m.sample("softshell_refused_no_memory_total", "", static_cast<double>(s.refused_no_memory));
    m.family("softshell_solves_total", "counter", "Deformation solves by outcome.");
    m.sample("softshell_solves_total", PrometheusText::label("outcome", "ok"), static_cast<double>(s.solves_ok));
    m.sample("softshell_solves_total", PrometheusText::label("outcome", "failed"), static_cast<double>(s.solves_failed));
    m.family("softshell_longpoll_waiters", "gauge", "Service-level latest_result waiters (HTTP and embedded).");
    m.sample("softshell_longpoll_waiters", "", static_cast<double>(s.waiters));
    m.family("softshell_solve_duration_seconds", "histogram", "Time of successful solves on a worker.");
    m.histogram("softshell_solve_duration_seconds", "", s.solve_seconds);
    m.family("softshell_precompute_duration_seconds", "histogram", "Time of successful precomputations.");
    m.histogram("softshell_precompute_duration_seconds", "", s.precompute_seconds);
    return m.take();
  }

  std::shared_ptr<service::Service> service;
  ServerOptions options;
  Listener server;
  std::vector<std::pair<std::regex, std::string>> routes;  // (pattern, method), for 405
  JsonGate json_gate;

  std::mutex lifecycle_mu;
  std::thread thread;
  std::stop_source stop_source;
  std::atomic<int> port{0};
  std::atomic<bool> started{false}, stopped{false};

  std::atomic<int> busy{0}, long_polls{0}, connection_threads{0};
  std::array<EndpointCounters, static_cast<size_t>(Endpoint::kCount)> counters;
};

HttpServer::HttpServer(std::shared_ptr<service::Service> service, ServerOptions options)
    : impl_(std::make_unique<Impl>(std::move(service), std::move(options))) {}

HttpServer::~HttpServer() { stop(); }

Result<int> HttpServer::start(const std::string& host, int port) {
  std::lock_guard lock(impl_->lifecycle_mu);
  if (impl_->started.load()) return Error{ErrorCode::kUnavailable, "the HTTP server was started already"};
  if (port < 0 || port > 65535) return Error{ErrorCode::kInvalidArgument, "port must be 0..65535"};
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
  impl_->server.raise_backlog(std::max(impl_->options.max_connections, 128));
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
  impl_->stop_source.request_stop();  // releases long polls and waiting deformation requests
  impl_->server.stop();
  if (impl_->thread.joinable()) impl_->thread.join();
}

int HttpServer::port() const { return impl_->port.load(); }
bool HttpServer::running() const { return impl_->started.load() && !impl_->stopped.load(); }
std::string HttpServer::metrics_text() const { return impl_->metrics_text(); }
int HttpServer::busy_connections() const { return impl_->busy.load(); }
int HttpServer::connection_threads() const { return impl_->connection_threads.load(); }
int HttpServer::waiting_long_polls() const { return impl_->long_polls.load(); }
const ServerOptions& HttpServer::options() const { return impl_->options; }
service::Service& HttpServer::service() const { return *impl_->service; }

std::vector<EndpointStats> HttpServer::endpoint_stats() const {
  std::vector<EndpointStats> out;
  for (size_t e = 0; e < impl_->counters.size(); ++e) {
    const auto& c = impl_->counters[e];
    out.push_back({std::string(kEndpointNames[e]), c.requests.load(), c.client_errors.load(), c.server_errors.load()});
  }
  return out;
}

}  // namespace softshell::http
