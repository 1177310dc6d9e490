// POST /geometries/{id}/results, GET .../results, .../results/{res_id}, .../results/{res_id}/request,
// .../latest_result, .../limit_comb.
#include <limits>

#include "context.h"

namespace softshell::http::internal {

namespace {

void deform(Context& c, const httplib::Request& req, httplib::Response& res) {
  const GeomId id = parse_id(req.matches[1].str());
  value_or_throw(c.service->info(id));  // 404 before anything else
  const wire::Format format = body_format_of(req);
  DeformationRequest request =
      decode<DeformationRequest>(c, req, format, &wire::decode_request_binary, &wire::decode_request_json);
  apply_model_param(req, request);
  const auto future = c.service->deform(id, std::move(request)).share();
  // The solve runs on a service worker; this connection thread only waits for it.
  try {
    wait_ready(c, future, std::chrono::hours(24 * 365));
  } catch (const Exception&) {
    throw Exception(ErrorCode::kUnavailable,
                    "the server is shutting down; the deformation may still be stored (see GET "
                    "/geometries/{id}/results)");
  }
  const auto stored = value_or_throw(future.get());
  write_result(req, res, *stored, format);
}

void latest(Context& c, const httplib::Request& req, httplib::Response& res) {
  const GeomId id = parse_id(req.matches[1].str());
  const uint32_t have = req.has_param("have") ? value_or_throw(parse_u32(req.get_param_value("have"), "have")) : 0;
  const double wait = wait_seconds(req, c.options);
  // A long poll holds this connection's thread: bound how many may do so at once.
  struct Slot {
    std::atomic<int>& count;
    bool held = false;
    ~Slot() {
      if (held) count.fetch_sub(1);
    }
  } slot{c.long_polls};
  if (wait > 0) {
    const int limit = std::max(1, c.options.max_connections - c.options.reserved_connections);
    if (c.long_polls.fetch_add(1) >= limit) {
      c.long_polls.fetch_sub(1);
      res.set_header("Retry-After", "1");
      throw Exception(ErrorCode::kUnavailable, "too many clients are waiting for results right now (" +
                                                   std::to_string(limit) + "); retry in a second");
    }
    slot.held = true;
  }
  const auto ms = std::chrono::milliseconds(static_cast<int64_t>(wait * 1000.0));
  const auto stored = value_or_throw(c.service->latest_result(id, have, ms, c.stop.get_token()));
  if (!stored) {
    res.status = 204;
    return;
  }
  write_result(req, res, *stored, wire::Format::kJson);
}

void limit_comb(Context& c, const httplib::Request& req, httplib::Response& res) {
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
  const uint32_t subface =
      req.has_param("subface") ? value_or_throw(parse_u32(req.get_param_value("subface"), "subface")) : 0;
  if (face > static_cast<uint32_t>(std::numeric_limits<int32_t>::max()) ||
      subface > static_cast<uint32_t>(std::numeric_limits<int32_t>::max())) {
    throw Exception(ErrorCode::kInvalidArgument, "face-index or subface out of range");
  }
  p.face = static_cast<int32_t>(face);
  p.subface = static_cast<int32_t>(subface);
  const LimitComb comb = value_or_throw(c.service->limit_comb(id, p));
  if (reply_format(req, wire::Format::kJson) == wire::Format::kBinary) {
    auto body = wire::encode_limit_comb_binary(comb);
    if (!body) throw Exception(ErrorCode::kNotAcceptable, body.error().message);
    res.set_content(std::move(*body), std::string(wire::kBinaryMediaType));
  } else {
    res.set_content(wire::encode_limit_comb_json(comb), std::string(wire::kJsonMediaType));
  }
}

}  // namespace

void add_result_routes(Router& r, Context& c) {
  using Req = const httplib::Request&;
  using Res = httplib::Response&;
  r.post(R"(/geometries/([^/]+)/results)", Endpoint::kDeform, [&c](Req req, Res res) { deform(c, req, res); });
  r.get(R"(/geometries/([^/]+)/results)", Endpoint::kResultIds, [&c](Req req, Res res) {
    const auto ids = value_or_throw(c.service->result_ids(parse_id(req.matches[1].str())));
    res.set_content(wire::encode_result_ids_json(ids), std::string(wire::kJsonMediaType));
  });
  r.get(R"(/geometries/([^/]+)/results/([^/]+))", Endpoint::kResult, [&c](Req req, Res res) {
    const GeomId id = parse_id(req.matches[1].str());
    const uint32_t k = value_or_throw(parse_u32(req.matches[2].str(), "res_id"));
    write_result(req, res, *value_or_throw(c.service->result(id, k)), wire::Format::kJson);
  });
  r.get(R"(/geometries/([^/]+)/results/([^/]+)/request)", Endpoint::kResultRequest, [&c](Req req, Res res) {
    const GeomId id = parse_id(req.matches[1].str());
    const uint32_t k = value_or_throw(parse_u32(req.matches[2].str(), "res_id"));
    const auto stored = value_or_throw(c.service->result(id, k));
    res.set_content(wire::encode_request_json(stored->request), std::string(wire::kJsonMediaType));
  });
  r.get(R"(/geometries/([^/]+)/latest_result)", Endpoint::kLatest, [&c](Req req, Res res) { latest(c, req, res); });
  r.get(R"(/geometries/([^/]+)/limit_comb)", Endpoint::kLimitComb, [&c](Req req, Res res) { limit_comb(c, req, res); });
}

}  // namespace softshell::http::internal
