// The browser client's routes (extensions.h): render tables, stresses and the web app's files.
// CORS is installed by server.cpp (it takes the server's OPTIONS routes and post-routing handler).
#include "context.h"
#include "extensions.h"

namespace softshell::http::internal {

void add_browser_routes(Router& r, Context& c) {
  using Req = const httplib::Request&;
  using Res = httplib::Response&;
  r.get(R"(/geometries/([^/]+)/render)", Endpoint::kRender, [&c](Req req, Res res) { render_route(*c.service, req, res); });
  r.get(R"(/geometries/([^/]+)/results/([^/]+)/stresses)", Endpoint::kStresses,
        [&c](Req req, Res res) { stresses_route(*c.service, req, res); });
  r.post(R"(/geometries/([^/]+)/results/([^/]+)/stresses)", Endpoint::kStresses,
         [&c](Req req, Res res) { stresses_route(*c.service, req, res); });
  r.get(R"(/|/index\.html|/app/[A-Za-z0-9._-]+)", Endpoint::kApp, [](Req req, Res res) {
    if (!app_route(req, res)) throw Exception(ErrorCode::kNotFound, "no file " + req.path + " in the web app");
  });
}

}  // namespace softshell::http::internal
