#include "context.h"

#include <cstdio>

namespace softshell::http::internal {

namespace {

constexpr std::array<std::string_view, kEndpointCount> kEndpointNames = {
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
    "PUT /geometries/{id}/holds/{hold_id}",
    "DELETE /geometries/{id}/holds/{hold_id}",
    "GET /geometries/{id}/holds",
    "GET /geometries/{id}/holds/{hold_id}",
    "GET /geometries/{id}/events",
    "GET /geometries/{id}/render",
    "GET|POST /geometries/{id}/results/{res_id}/stresses",
    "GET /, /app/{file}",
    "DELETE /geometries/{id}",
    "unmatched",
};

}  // namespace

std::string_view endpoint_name(Endpoint e) { return kEndpointNames[static_cast<size_t>(e)]; }

Context::Context(std::shared_ptr<service::Service> s, ServerOptions o)
    : service(std::move(s)),
      options(std::move(o)),
      json_gate(options.max_json_decode_bytes ? options.max_json_decode_bytes : size_t{1} << 30) {}

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

wire::Format body_format_of(const httplib::Request& req) {
  return value_or_throw(body_format(req.get_header_value("Content-Type")));
}

wire::Format reply_format(const httplib::Request& req, wire::Format fallback) {
  return response_format(req.get_header_value("Accept"), fallback);
}

void apply_model_param(const httplib::Request& req, DeformationRequest& request) {
  if (!req.has_param("model")) return;
  const std::string name = req.get_param_value("model");
  const DeformationModel model = value_or_throw(wire::parse_deformation_model(name));
  if (model != request.model && request.model != DeformationModel::kLinear) {
    throw Exception(ErrorCode::kInvalidArgument,
                    "the query says model=" + name + " but the body's \"model\" field says otherwise: give one");
  }
  request.model = model;
}

double wait_seconds(const httplib::Request& req, const ServerOptions& options) {
  double wait = options.default_wait_seconds;
  if (req.has_param("wait")) {
    wait = value_or_throw(parse_number(req.get_param_value("wait"), "wait"));
    if (wait < 0) throw Exception(ErrorCode::kInvalidArgument, "'wait' must be >= 0 seconds");
  }
  return std::min(wait, options.max_wait_seconds);
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
  } else if (stored.holds) {
    res.set_content(wire::encode_result_json(result, *stored.holds), std::string(wire::kJsonMediaType));
  } else {
    res.set_content(wire::encode_result_json(result), std::string(wire::kJsonMediaType));
  }
}

httplib::Server::Handler Router::wrap(Endpoint endpoint, Handler fn) const {
  return [this, endpoint, fn = std::move(fn)](const httplib::Request& req, httplib::Response& res) {
    set_endpoint(endpoint);
    try {
      fn(req, res);
    } catch (...) {
      set_error(res, describe(std::current_exception()));
    }
  };
}

void Router::get(const char* pattern, Endpoint e, Handler h) {
  server_.Get(pattern, wrap(e, std::move(h)));
  routes_.emplace_back(std::regex(pattern), "GET");
}
void Router::post(const char* pattern, Endpoint e, Handler h) {
  server_.Post(pattern, wrap(e, std::move(h)));
  routes_.emplace_back(std::regex(pattern), "POST");
}
void Router::put(const char* pattern, Endpoint e, Handler h) {
  server_.Put(pattern, wrap(e, std::move(h)));
  routes_.emplace_back(std::regex(pattern), "PUT");
}
void Router::del(const char* pattern, Endpoint e, Handler h) {
  server_.Delete(pattern, wrap(e, std::move(h)));
  routes_.emplace_back(std::regex(pattern), "DELETE");
}

std::string Router::allowed_methods(const std::string& path) const {
  std::string allowed;
  for (const auto& [pattern, method] : routes_) {
    if (std::regex_match(path, pattern) && allowed.find(method) == std::string::npos) {
      allowed += (allowed.empty() ? "" : ", ") + method;
    }
  }
  return allowed;
}

}  // namespace softshell::http::internal
