// GET /health and GET /metrics.
#include "context.h"

namespace softshell::http::internal {

void add_service_routes(Router& r, Context& c) {
  using Req = const httplib::Request&;
  using Res = httplib::Response&;
  r.get(R"(/health)", Endpoint::kHealth, [&c](Req, Res res) {
    if (c.stopping()) {
      set_error(res, Error{ErrorCode::kUnavailable, "the server is shutting down"});
      return;
    }
    res.set_content(std::string(R"({"status":"ok","version":")") + SOFTSHELL_VERSION_STRING + "\"}",
                    std::string(wire::kJsonMediaType));
  });
  r.get(R"(/metrics)", Endpoint::kMetrics, [&c](Req, Res res) {
    res.set_content(c.metrics(), "text/plain; version=0.0.4; charset=utf-8");
  });
}

}  // namespace softshell::http::internal
