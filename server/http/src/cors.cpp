// CORS for pages served from other origins (--cors-origin): preflight answers and the headers of
// every response whose Origin is allowed. Off (nothing installed) without origins.
#include <algorithm>

#include "extensions.h"

namespace softshell::http::internal {

namespace {

constexpr const char* kMethods = "GET, POST, PUT, DELETE, OPTIONS";
constexpr const char* kHeaders = "Content-Type, Accept, Last-Event-ID, Authorization";
constexpr const char* kExposed = "ETag, Retry-After, Allow, WWW-Authenticate";

bool allowed(const std::vector<std::string>& origins, const std::string& origin) {
  if (origin.empty()) return false;
  return std::any_of(origins.begin(), origins.end(), [&](const std::string& o) { return o == "*" || o == origin; });
}

}  // namespace

std::string cors_header_lines(const std::vector<std::string>& origins, const std::string& origin) {
  if (!allowed(origins, origin)) return {};
  return "Access-Control-Allow-Origin: " + origin + "\r\nVary: Origin\r\nAccess-Control-Expose-Headers: " + kExposed +
         "\r\n";
}

void install_cors(httplib::Server& server, const std::vector<std::string>& origins) {
  if (origins.empty()) return;
  server.Options(R"(/.*)", [origins](const httplib::Request& req, httplib::Response& res) {
    const std::string origin = req.get_header_value("Origin");
    res.status = 204;
    if (!allowed(origins, origin)) return;  // the browser refuses the request: no headers
    res.set_header("Access-Control-Allow-Methods", kMethods);
    res.set_header("Access-Control-Allow-Headers", kHeaders);
    res.set_header("Access-Control-Max-Age", "600");
  });
  server.set_post_routing_handler([origins](const httplib::Request& req, httplib::Response& res) {
    const std::string origin = req.get_header_value("Origin");
    if (!allowed(origins, origin)) return;
    // The requesting origin, not "*": a page's credentials-free requests work either way, and an
    // explicit origin works with caches (Vary).
    res.set_header("Access-Control-Allow-Origin", origin);
    res.set_header("Vary", "Origin");
    res.set_header("Access-Control-Expose-Headers", kExposed);
  });
}

}  // namespace softshell::http::internal
