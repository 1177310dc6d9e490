#pragma once
/// \file
/// \brief `HttpServer`: the HTTP API of PROTOCOL.md over a `service::Service` (cpp-httplib).
///
/// Handlers are thin: parse the request, call the service, serialize the answer. Every error is
/// the JSON error of PROTOCOL.md with its status; a client's mistake is never a 5xx.
///
/// Threads: every open connection is served by its own I/O thread (cpp-httplib's model), taken
/// from a pool that grows on demand up to `max_connections`; I/O threads only parse, wait and
/// write. Solves and precomputations run on the service's fixed pools, so long polls (which hold
/// an I/O thread while they wait) can never starve a computation, and at most
/// `max_connections - reserved_connections` connections may long-poll at once, so waiters cannot
/// starve other requests of I/O threads either. Event streams (`GET .../events`) hold no I/O
/// thread: once their request is checked, the socket goes to an event writer thread (of
/// `event_writers`), which serves its share of the streams over non-blocking sockets (each
/// result serialized once for all of them, latest wins per stream),
/// so they count against the file descriptor limit and the service's memory budget only.

#include <chrono>
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "softshell/result.h"
#include "softshell/service/log.h"
#include "softshell/service/service.h"

namespace softshell::http {

/// Configuration of an `HttpServer`.
struct ServerOptions {
  /// What decoding a JSON body takes, in multiples of its size (see max_json_decode_bytes).
  static constexpr size_t kJsonDecodeFactor = 40;
  /// Largest request body (bytes); larger bodies get 413.
  size_t max_body_bytes = size_t{64} << 20;
  /// Memory that JSON bodies being decoded at once may take. A JSON body takes up to
  /// `kJsonDecodeFactor` times its size while parsed (measured: 33.7x for 50 MB of constraints),
  /// so one whose decoding alone would take more than this gets 413 (send the binary layout);
  /// beyond it, while others are decoded, a request gets 507 and may retry. 0 = 1 GiB.
  size_t max_json_decode_bytes = 0;
  /// Open connections served at once (one I/O thread each); more wait to be accepted.
  int max_connections = 1024;
  /// I/O threads kept free of long polls: at most max_connections - reserved_connections
  /// `latest_result` requests wait at once; more get 503 with `Retry-After: 1`.
  int reserved_connections = 32;
  /// An idle keep-alive connection is closed after this long (also bounds how long `stop` waits
  /// for idle connections).
  std::chrono::seconds keep_alive_timeout{5};
  /// Time allowed to receive a request and to send a response.
  std::chrono::seconds io_timeout{30};
  /// A request's line and headers must arrive within this time (408 otherwise) and this size
  /// (431 otherwise), so slow or endless senders hold an I/O thread for seconds only.
  std::chrono::milliseconds head_timeout{10000};
  size_t max_head_bytes = 64 * 1024;
  /// Connections one client address may have open at once (0: no limit); beyond it a connection
  /// gets 503 with `Retry-After: 1`, so one client cannot take every I/O thread. Behind a proxy
  /// on the same host every client has the proxy's address: leave it 0 and limit at the proxy.
  int max_connections_per_address = 0;
  /// An I/O thread idle this long exits (at least 8 are kept), so a burst of clients leaves no
  /// crowd of idle threads behind.
  std::chrono::milliseconds idle_thread_exit{30000};
  /// `wait` default and upper bound of `latest_result` and of hold PUTs and DELETEs (PROTOCOL.md:
  /// 25 and 60 seconds).
  double default_wait_seconds = 25.0;
  double max_wait_seconds = 60.0;
  /// An event stream that had nothing to send for this long gets a `: keep-alive` comment
  /// (PROTOCOL.md: at least every 15 s).
  std::chrono::milliseconds event_keep_alive{10000};
  /// An event stream whose client takes no bytes for this long is closed (its newest frame
  /// waits meanwhile; nothing older is queued).
  std::chrono::milliseconds event_stall_timeout{30000};
  /// Threads that write event streams (each serves a share of the streams over epoll); 0 = half
  /// the hardware threads, at least 1 (the other half is left to solves and requests).
  int event_writers = 0;
  /// Origins allowed to call the API from pages served elsewhere (CORS; "*" = any origin):
  /// preflight requests are answered and responses carry Access-Control-Allow-Origin. Empty
  /// (the default): no CORS headers, browsers allow only same-origin pages (the app at /).
  std::vector<std::string> cors_origins;
  /// Access token every request needs as `Authorization: Bearer <token>`, but `GET /health`, the
  /// browser app's files and CORS preflights (softshell/http/auth.h); others get 401. Empty (the
  /// default): no authentication. `start` refuses a token `check_auth_token` refuses.
  std::string auth_token;
  /// Where request lines (`info`: method, path, status, microseconds) and handler failures
  /// (`error`) go.
  service::Logger logger;
};

/// Request counters of one endpoint (for tests and /metrics).
struct EndpointStats {
  std::string endpoint;  ///< e.g. "POST /geometries/{id}/results"
  uint64_t requests = 0;
  uint64_t client_errors = 0;  ///< 4xx
  uint64_t server_errors = 0;  ///< 5xx
};

/// The HTTP front end of a service.
///
/// Thread-safety: `start`, `stop` and the accessors may be called from any thread; `stop` is
/// idempotent and is also called by the destructor.
class HttpServer {
 public:
  HttpServer(std::shared_ptr<service::Service> service, ServerOptions options = {});
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  /// Binds `host:port` (port 0 = any free port) and serves on a background thread. Returns the
  /// bound port; kUnavailable if the address cannot be bound or the server already started.
  Result<int> start(const std::string& host, int port);

  /// Stops accepting, answers waiting long polls, deformation requests and hold changes with 503,
  /// ends every event stream after the event it is writing (the end of its chunked body), lets
  /// running requests finish and joins every thread. The service keeps running.
  void stop();

  /// The bound port, or 0 before `start`.
  int port() const;
  bool running() const;

  /// The text `GET /metrics` answers (Prometheus exposition format).
  std::string metrics_text() const;
  /// Counters per endpoint.
  std::vector<EndpointStats> endpoint_stats() const;
  /// Connections (I/O threads) busy right now, I/O threads alive (busy or idle), long polls
  /// waiting right now, and event streams open.
  int busy_connections() const;
  int connection_threads() const;
  int waiting_long_polls() const;
  int event_streams() const;

  const ServerOptions& options() const;
  service::Service& service() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace softshell::http
