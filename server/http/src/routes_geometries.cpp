// POST /geometries, GET /geometries, GET and DELETE /geometries/{id}, GET /geometries/{id}/status.
#include "context.h"

namespace softshell::http::internal {

namespace {

void upload(Context& c, const httplib::Request& req, httplib::Response& res) {
  const wire::Format format = body_format_of(req);
  Geometry g = decode<Geometry>(c, req, format, &wire::decode_geometry_binary, &wire::decode_geometry_json);
  const std::string ns = req.has_param("namespace") ? req.get_param_value("namespace") : std::string();
  const UploadResult up = value_or_throw(c.service->upload(std::move(g.mesh), g.material, ns));
  res.status = up.created ? 201 : 200;
  if (reply_format(req, format) == wire::Format::kBinary) {
    res.set_content(wire::encode_upload_response_binary(up.id), std::string(wire::kBinaryMediaType));
  } else {
    res.set_content(wire::encode_upload_response_json(up.id, up.status), std::string(wire::kJsonMediaType));
  }
}

void geometry(Context& c, const httplib::Request& req, httplib::Response& res) {
  const GeomId id = parse_id(req.matches[1].str());
  const auto g = value_or_throw(c.service->geometry(id));
  if (reply_format(req, wire::Format::kJson) == wire::Format::kBinary) {
    if (!wire::geometry_fits_binary(g->mesh)) {
      throw Exception(ErrorCode::kNotAcceptable,
                      "geometry " + id.hex() +
                          " has no binary layout (it has faces that are not quads, crease or corner tags, or "
                          "boundary \"none\"); ask for application/json");
    }
    auto body = wire::encode_geometry_binary(g->mesh, g->material);
    if (!body) throw Exception(ErrorCode::kNotAcceptable, body.error().message);
    res.set_content(std::move(*body), std::string(wire::kBinaryMediaType));
  } else {
    res.set_content(wire::encode_geometry_json(g->mesh, g->material, id, g->name_space),
                    std::string(wire::kJsonMediaType));
  }
}

}  // namespace

void add_geometry_routes(Router& r, Context& c) {
  using Req = const httplib::Request&;
  using Res = httplib::Response&;
  r.post(R"(/geometries)", Endpoint::kUpload, [&c](Req req, Res res) { upload(c, req, res); });
  r.get(R"(/geometries)", Endpoint::kList, [&c](Req, Res res) {
    res.set_content(wire::encode_geometry_list_json(c.service->geometries()), std::string(wire::kJsonMediaType));
  });
  r.get(R"(/geometries/([^/]+))", Endpoint::kGeometry, [&c](Req req, Res res) { geometry(c, req, res); });
  // Everything kept for the geometry goes; whoever waits on it gets 410 (Service::remove).
  r.del(R"(/geometries/([^/]+))", Endpoint::kDeleteGeometry, [&c](Req req, Res res) {
    value_or_throw(c.service->remove(parse_id(req.matches[1].str())));
    res.status = 204;
  });
  r.get(R"(/geometries/([^/]+)/status)", Endpoint::kStatus, [&c](Req req, Res res) {
    const auto info = value_or_throw(c.service->info(parse_id(req.matches[1].str())));
    res.set_content(wire::encode_geometry_info_json(info), std::string(wire::kJsonMediaType));
  });
}

}  // namespace softshell::http::internal
