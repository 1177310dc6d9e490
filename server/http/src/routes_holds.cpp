// PUT/DELETE/GET /geometries/{id}/holds/{hold_id} and GET /geometries/{id}/holds (PROTOCOL.md v2).
#include <cmath>

#include "context.h"

namespace softshell::http::internal {

namespace {

std::string hold_id_of(const httplib::Request& req) {
  std::string id = req.matches[2].str();
  value_or_throw(wire::check_hold_id(id));
  return id;
}

std::chrono::milliseconds ttl_of(const httplib::Request& req) {
  if (!req.has_param("ttl")) return std::chrono::milliseconds(10000);
  const double ttl = value_or_throw(parse_number(req.get_param_value("ttl"), "ttl"));
  if (!(ttl > 0.0) || ttl > 600.0) {
    throw Exception(ErrorCode::kInvalidArgument,
                    "'ttl' (the hold's lease in seconds) must be more than 0 and at most 600, got " +
                        req.get_param_value("ttl").substr(0, 40));
  }
  return std::chrono::milliseconds(std::max<int64_t>(1, std::llround(ttl * 1000.0)));
}

// The answer of a PUT or DELETE: the first result that includes the change, or 202 when it is not
// there within `wait` (or the hold state became unsolvable by a release merged into the same solve).
void answer(Context& c, const httplib::Request& req, httplib::Response& res, const service::HoldTicket& ticket,
            double wait, wire::Format fallback) {
  const auto ms = std::chrono::milliseconds(static_cast<int64_t>(wait * 1000.0));
  if (wait > 0 && wait_ready(c, ticket.outcome, ms)) {
    const service::HoldOutcome outcome = value_or_throw(ticket.outcome.get());
    if (outcome.result) {
      write_result(req, res, *outcome.result, fallback);
      return;
    }
  }
  res.status = 202;
  res.set_content(wire::encode_hold_accepted_json(ticket.hold_id, ticket.version), std::string(wire::kJsonMediaType));
}

void put_hold(Context& c, const httplib::Request& req, httplib::Response& res) {
  const GeomId id = parse_id(req.matches[1].str());
  const std::string hold_id = hold_id_of(req);
  value_or_throw(c.service->info(id));  // 404 before the body
  const auto ttl = ttl_of(req);
  const double wait = wait_seconds(req, c.options);
  const wire::Format format = body_format_of(req);
  DeformationRequest request =
      decode<DeformationRequest>(c, req, format, &wire::decode_request_binary, &wire::decode_request_json);
  apply_model_param(req, request);
  const service::HoldTicket ticket = value_or_throw(c.service->put_hold(id, hold_id, std::move(request), {ttl}));
  answer(c, req, res, ticket, wait, format);
}

void release_hold(Context& c, const httplib::Request& req, httplib::Response& res) {
  const GeomId id = parse_id(req.matches[1].str());
  const std::string hold_id = hold_id_of(req);
  const double wait = wait_seconds(req, c.options);
  const service::HoldTicket ticket = value_or_throw(c.service->release_hold(id, hold_id));
  answer(c, req, res, ticket, wait, wire::Format::kJson);
}

}  // namespace

void add_hold_routes(Router& r, Context& c) {
  using Req = const httplib::Request&;
  using Res = httplib::Response&;
  r.put(R"(/geometries/([^/]+)/holds/([^/]+))", Endpoint::kPutHold, [&c](Req req, Res res) { put_hold(c, req, res); });
  r.del(R"(/geometries/([^/]+)/holds/([^/]+))", Endpoint::kDeleteHold,
        [&c](Req req, Res res) { release_hold(c, req, res); });
  r.get(R"(/geometries/([^/]+)/holds)", Endpoint::kHolds, [&c](Req req, Res res) {
    const auto list = value_or_throw(c.service->holds(parse_id(req.matches[1].str())));
    res.set_content(wire::encode_hold_list_json(list), std::string(wire::kJsonMediaType));
  });
  r.get(R"(/geometries/([^/]+)/holds/([^/]+))", Endpoint::kHold, [&c](Req req, Res res) {
    const GeomId id = parse_id(req.matches[1].str());
    const auto hold = value_or_throw(c.service->hold(id, hold_id_of(req)));
    res.set_content(wire::encode_hold_json(hold), std::string(wire::kJsonMediaType));
  });
}

}  // namespace softshell::http::internal
