// GET /geometries/{id}/events: Server-Sent Events (PROTOCOL.md v2). The checks are answered here;
// the stream itself is handed to the event writer (event_hub.h), which owns the socket from then on.
#include "context.h"
#include "extensions.h"

namespace softshell::http::internal {

namespace {

void events(Context& c, const httplib::Request& req, httplib::Response& res) {
  if (c.stopping()) throw Exception(ErrorCode::kUnavailable, "the server is shutting down");
  const GeomId id = parse_id(req.matches[1].str());
  value_or_throw(c.service->info(id));
  // A reconnecting EventSource sends the id of the last event it got; it takes precedence.
  uint32_t have = 0;
  if (const std::string last = req.get_header_value("Last-Event-ID"); !last.empty()) {
    have = value_or_throw(parse_u32(last, "Last-Event-ID"));
  } else if (req.has_param("have")) {
    have = value_or_throw(parse_u32(req.get_param_value("have"), "have"));
  }
  Connection* connection = current_connection();
  if (!connection) throw Exception(ErrorCode::kInternal, "an event stream outside a connection");
  auto ticket = value_or_throw(c.events->open(id));
  const int fd = connection->take();
  // The writer sends the head itself, so the CORS headers (--cors-origin) go with it.
  std::string extra = cors_header_lines(c.options.cors_origins, req.get_header_value("Origin"));
  c.events->attach(std::move(ticket), fd, have, req.version == "HTTP/1.0", std::move(extra));
  res.status = 200;  // for the log; the writer sends the head
}

}  // namespace

void add_event_routes(Router& r, Context& c) {
  r.get(R"(/geometries/([^/]+)/events)", Endpoint::kEvents,
        [&c](const httplib::Request& req, httplib::Response& res) { events(c, req, res); });
}

}  // namespace softshell::http::internal
