#pragma once
// The browser client's routes (private to the HTTP layer), written against the handler
// signature only so that they register with one line wherever the routes are wired:
//   GET  /geometries/{id}/render?level=L               render tables (routes_render.cpp)
//   GET|POST /geometries/{id}/results/{res_id}/stresses stresses (routes_render.cpp)
//   GET  /, /app/{file}                                the web app (routes_app.cpp)
//   OPTIONS *, CORS headers                            --cors-origin (cors.cpp)

#include <string>
#include <vector>

#include "softshell/service/service.h"

#include <httplib.h>  // after Eigen (service.h): <resolv.h> defines a macro `_res` that Eigen uses as a name

namespace softshell::http::internal {

// Handlers: they throw softshell::Exception for errors (the caller's wrapper answers them).
void render_route(const service::Service& service, const httplib::Request& req, httplib::Response& res);
void stresses_route(const service::Service& service, const httplib::Request& req, httplib::Response& res);
// Answers GET / and GET /app/{file} from the files built into the library; false (res untouched)
// for an unknown file.
bool app_route(const httplib::Request& req, httplib::Response& res);

// With a non-empty `origins` ("*" = any): answers preflight (OPTIONS) requests and adds the CORS
// headers to every response whose Origin is allowed. Takes the server's OPTIONS routes and its
// post-routing handler.
void install_cors(httplib::Server& server, const std::vector<std::string>& origins);
// The CORS header lines ("Name: value\r\n"...) for a response to `origin`, "" if not allowed
// (for responses written outside cpp-httplib, such as event streams).
std::string cors_header_lines(const std::vector<std::string>& origins, const std::string& origin);

}  // namespace softshell::http::internal
