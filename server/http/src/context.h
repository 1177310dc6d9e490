#pragma once
// What the route handlers share (private to the HTTP layer): the context, request helpers, and
// the router that labels every route for logs and metrics.

#include <array>
#include <atomic>
#include <chrono>
#include <functional>
#include <future>
#include <memory>
#include <regex>
#include <stop_token>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "server_header.h"
#include "event_hub.h"
#include "json_gate.h"
#include "softshell/http/negotiation.h"
#include "softshell/http/server.h"
#include "softshell/wire.h"
#include "listener.h"  // last: httplib.h (see listener.h)

namespace softshell::http::internal {

// --- endpoints: labels for logs and metrics ---------------------------------------------------

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
  kPutHold,
  kDeleteHold,
  kHolds,
  kHold,
  kEvents,
  kRender,
  kStresses,
  kApp,
  kDeleteGeometry,
  kUnmatched,
  kCount
};
inline constexpr size_t kEndpointCount = static_cast<size_t>(Endpoint::kCount);
std::string_view endpoint_name(Endpoint e);

// Marks the request this thread serves as one of `endpoint` (server.cpp keeps the per-thread
// request context that the logger reads).
void set_endpoint(Endpoint endpoint);

// --- the context ------------------------------------------------------------------------------

struct Context {
  Context(std::shared_ptr<service::Service> s, ServerOptions o);

  std::shared_ptr<service::Service> service;
  ServerOptions options;
  JsonGate json_gate;
  std::stop_source stop;            // requested by HttpServer::stop: waits end with 503
  std::atomic<int> long_polls{0};   // latest_result requests waiting now
  std::unique_ptr<EventHub> events;
  std::function<std::string()> metrics;  // the text of GET /metrics

  bool stopping() const { return stop.stop_requested() || service->shutting_down(); }
};

// --- request helpers --------------------------------------------------------------------------

template <class T>
T value_or_throw(Result<T> r) {
  if (!r) throw Exception(r.error());
  return std::move(r).value();
}
inline void value_or_throw(Result<void> r) {
  if (!r) throw Exception(r.error());
}

GeomId parse_id(std::string_view text);
void set_error(httplib::Response& res, const Error& error);
std::string mib(size_t bytes);
wire::Format body_format_of(const httplib::Request& req);
wire::Format reply_format(const httplib::Request& req, wire::Format fallback);
// A `wait` query parameter in seconds: default and upper bound from the options; 400 below 0.
double wait_seconds(const httplib::Request& req, const ServerOptions& options);
/// Applies the query parameter `model=linear|nonlinear` (PROTOCOL.md, the nonlinear model: it
/// works with both body layouts) to a decoded request; a parameter that contradicts the body's
/// "model" field, or an unknown model, is a 400.
void apply_model_param(const httplib::Request& req, DeformationRequest& request);

// Decodes a body in `format`, bounding the memory of the JSON bodies decoded at once (413 for a
// body that alone would take more than the whole budget, 507 while others take it).
template <class T>
T decode(Context& c, const httplib::Request& req, wire::Format format, Result<T> (*binary)(std::string_view),
         Result<T> (*json)(std::string_view)) {
  if (format == wire::Format::kBinary) return value_or_throw(binary(req.body));
  const size_t cost = req.body.size() * ServerOptions::kJsonDecodeFactor;
  if (cost > c.json_gate.budget()) {
    throw Exception(ErrorCode::kPayloadTooLarge,
                    "a JSON body of " + mib(req.body.size()) + " is larger than this server decodes (" +
                        mib(c.json_gate.budget() / ServerOptions::kJsonDecodeFactor) +
                        "; JSON takes about " + std::to_string(ServerOptions::kJsonDecodeFactor) +
                        " times its size while parsed): send the binary layout, or split the request");
  }
  if (!c.json_gate.enter(cost)) {
    throw Exception(ErrorCode::kResourceExhausted,
                    "the server is decoding other large JSON bodies right now; retry shortly or send the binary "
                    "format");
  }
  struct Leave {
    JsonGate& gate;
    size_t cost;
    ~Leave() { gate.leave(cost); }
  } leave{c.json_gate, cost};
  return value_or_throw(json(req.body));
}

// A stored result in the result layout (binary or JSON per Accept, else `fallback`); the JSON
// form of a hold-state result carries its `holds` map.
void write_result(const httplib::Request& req, httplib::Response& res, const service::StoredResult& stored,
                  wire::Format fallback);

// Waits for `future` up to `wait` (0: not at all), in slices, giving up with 503 when the server
// stops. False if it is not ready in time.
template <class T>
bool wait_ready(const Context& c, const std::shared_future<T>& future, std::chrono::milliseconds wait) {
  const auto deadline = std::chrono::steady_clock::now() + wait;
  const auto stop = c.stop.get_token();
  for (;;) {
    const auto left = deadline - std::chrono::steady_clock::now();
    if (left <= std::chrono::steady_clock::duration::zero()) return future.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
    const auto slice = std::min<std::chrono::steady_clock::duration>(left, std::chrono::milliseconds(50));
    if (future.wait_for(slice) == std::future_status::ready) return true;
    if (stop.stop_requested()) throw Exception(ErrorCode::kUnavailable, "the server is shutting down");
  }
}

// An exception from a handler as the error to answer with (bugs go to the SDK log sink).
inline Error describe(std::exception_ptr ep) { return error_from(std::move(ep), "handling this request"); }

// --- routing ----------------------------------------------------------------------------------

class Router {
 public:
  using Handler = std::function<void(const httplib::Request&, httplib::Response&)>;
  explicit Router(httplib::Server& server) : server_(server) {}

  void get(const char* pattern, Endpoint e, Handler h);
  void post(const char* pattern, Endpoint e, Handler h);
  void put(const char* pattern, Endpoint e, Handler h);
  void del(const char* pattern, Endpoint e, Handler h);

  // The methods routed for `path`, e.g. "GET, POST" ("" for an unknown path).
  std::string allowed_methods(const std::string& path) const;

 private:
  httplib::Server::Handler wrap(Endpoint e, Handler h) const;

  httplib::Server& server_;
  std::vector<std::pair<std::regex, std::string>> routes_;
};

// The routes, by resource.
void add_service_routes(Router& r, Context& c);   // /health, /metrics
void add_geometry_routes(Router& r, Context& c);  // /geometries, /geometries/{id} (GET, DELETE), .../status
void add_result_routes(Router& r, Context& c);    // .../results..., .../latest_result, .../limit_comb
void add_hold_routes(Router& r, Context& c);      // .../holds, .../holds/{hold_id}
void add_event_routes(Router& r, Context& c);     // .../events
void add_browser_routes(Router& r, Context& c);   // .../render, .../results/{res_id}/stresses, /, /app/{file}

}  // namespace softshell::http::internal
