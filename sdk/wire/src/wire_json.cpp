// JSON layouts of PROTOCOL.md (and the documented extensions).
//
// (Long, on purpose: every JSON body's reader and writer side by side, sharing one set of strict
// field readers, so a layout's rules and its error messages live in one place.)
//
// Request bodies (uploads, deformation requests) are strict: unknown fields are an error, so a
// typo never silently changes a simulation. Response bodies are lenient: unknown fields are
// ignored, so clients keep working against newer servers.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <string>
#include <unordered_set>
#include <vector>

#include <nlohmann/json.hpp>

#include "softshell/wire.h"
#include "wire_internal.h"

namespace softshell::wire {
namespace {

using json = nlohmann::json;
using softshell::describe_number;

[[noreturn]] void bad(const std::string& message) { fail(ErrorCode::kInvalidArgument, message); }

// ---------------------------------------------------------------------------------------------
// Writing: numbers in the shortest form that reads back exactly.

class JsonOut {
 public:
  JsonOut& raw(std::string_view s) {
    out_.append(s);
    return *this;
  }
  JsonOut& number(double v) {
    if (!std::isfinite(v)) fail(ErrorCode::kInvalidArgument, "cannot write " + describe_number(v) + " as JSON");
    if (v == 0.0) v = 0.0;  // no "-0"
    char buf[32];
    auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, v);
    out_.append(buf, ptr);
    return *this;
  }
  JsonOut& integer(int64_t v) {
    char buf[24];
    auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, v);
    out_.append(buf, ptr);
    return *this;
  }
  JsonOut& string(std::string_view s) {
    out_.append(json(std::string(s)).dump(-1, ' ', false, json::error_handler_t::replace));
    return *this;
  }
  JsonOut& key(std::string_view k) {
    string(k);
    out_.push_back(':');
    return *this;
  }
  JsonOut& vec3(const Vec3& v) {
    out_.push_back('[');
    number(v.x()).raw(",").number(v.y()).raw(",").number(v.z());
    out_.push_back(']');
    return *this;
  }
  template <class T, class Fn>
  JsonOut& array(const std::vector<T>& items, Fn&& write_item) {
    out_.push_back('[');
    for (size_t i = 0; i < items.size(); ++i) {
      if (i) out_.push_back(',');
      write_item(items[i]);
    }
    out_.push_back(']');
    return *this;
  }
  JsonOut& numbers(const std::vector<double>& v) {
    return array(v, [&](double x) { number(x); });
  }
  JsonOut& integers(const std::vector<int32_t>& v) {
    return array(v, [&](int32_t x) { integer(x); });
  }
  std::string take() { return std::move(out_); }

 private:
  std::string out_;
};

std::string_view boundary_name(BoundaryMode mode) {
  return mode == BoundaryMode::kNone ? "none" : "edge_and_corner";
}

// ---------------------------------------------------------------------------------------------
// Reading

// Rejects nesting deeper than kMaxJsonDepth before the parser builds anything.
void check_depth(std::string_view body) {
  int depth = 0;
  bool in_string = false, escaped = false;
  for (char c : body) {
    if (in_string) {
      if (escaped) escaped = false;
      else if (c == '\\') escaped = true;
      else if (c == '"') in_string = false;
      continue;
    }
    if (c == '"') in_string = true;
    else if (c == '[' || c == '{') {
      if (++depth > kMaxJsonDepth) {
        bad("the JSON is nested more than " + std::to_string(kMaxJsonDepth) + " levels deep");
      }
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
}

// A key repeated in one object: the strict-request policy refuses it (nlohmann keeps the last
// one silently).
struct DuplicateKey {
  std::string key;
};

json parse(std::string_view body) {
  check_depth(body);
  std::vector<std::unordered_set<std::string>> keys;  // per open object, the keys seen so far
  const json::parser_callback_t strict = [&keys](int, json::parse_event_t event, json& parsed) {
    switch (event) {
      case json::parse_event_t::object_start: keys.emplace_back(); break;
      case json::parse_event_t::object_end:
        if (!keys.empty()) keys.pop_back();
        break;
      case json::parse_event_t::key: {
        const std::string& key = parsed.get_ref<const std::string&>();
        if (!keys.back().insert(key).second) throw DuplicateKey{key};
        break;
      }
      default: break;
    }
    return true;
  };
  try {
    return json::parse(body.begin(), body.end(), strict);
  } catch (const DuplicateKey& d) {
    bad("invalid JSON: the key \"" + d.key.substr(0, 64) + "\" appears twice in one object; each key may appear once");
  } catch (const json::exception& e) {
    // "[json.exception.parse_error.101] parse error at line 1, ..." -> "parse error at line 1, ..."
    std::string what = e.what();
    if (auto close = what.find("] "); what.rfind("[json.exception.", 0) == 0 && close != std::string::npos) {
      what = what.substr(close + 2);
    }
    bad("invalid JSON: " + what);
  }
}

std::string join(const std::string& path, std::string_view key) {
  return path.empty() ? std::string(key) : path + "." + std::string(key);
}
std::string item(const std::string& path, size_t i) { return path + "[" + std::to_string(i) + "]"; }
std::string where(const std::string& path) { return path.empty() ? "the body" : "'" + path + "'"; }

const char* type_name(const json& j) {
  switch (j.type()) {
    case json::value_t::null: return "null";
    case json::value_t::object: return "an object";
    case json::value_t::array: return "an array";
    case json::value_t::string: return "a string";
    case json::value_t::boolean: return "a boolean";
    case json::value_t::number_integer:
    case json::value_t::number_unsigned:
    case json::value_t::number_float: return "a number";
    default: return "an unsupported value";
  }
}

const json& object(const json& j, const std::string& path) {
  if (!j.is_object()) bad(where(path) + " must be a JSON object, got " + type_name(j));
  return j;
}

const json& array(const json& j, const std::string& path) {
  if (!j.is_array()) bad(where(path) + " must be a JSON array, got " + type_name(j));
  return j;
}

// Unknown keys are an error in request bodies.
void known_keys(const json& obj, std::initializer_list<std::string_view> known, const std::string& path) {
  for (auto it = obj.begin(); it != obj.end(); ++it) {
    bool ok = false;
    for (auto k : known) ok = ok || it.key() == k;
    if (!ok) {
      std::string list;
      for (auto k : known) list += (list.empty() ? "" : ", ") + std::string(k);
      std::string key = it.key().size() > 40 ? it.key().substr(0, 40) + "..." : it.key();
      bad("unknown field " + json(key).dump(-1, ' ', true, json::error_handler_t::replace) + " in " + where(path) +
          " (known fields: " + list + ")");
    }
  }
}

const json* find(const json& obj, std::string_view key) {
  auto it = obj.find(key);
  return it == obj.end() ? nullptr : &*it;
}

const json& require(const json& obj, std::string_view key, const std::string& path) {
  const json* v = find(obj, key);
  if (!v) bad(where(path) + " needs the field '" + std::string(key) + "'");
  return *v;
}

double number(const json& j, const std::string& path) {
  if (!j.is_number()) bad(where(path) + " must be a number, got " + type_name(j));
  const double v = j.get<double>();
  if (!std::isfinite(v)) bad(where(path) + " must be finite, got " + describe_number(v));
  return v;
}

int64_t integer(const json& j, const std::string& path, int64_t lo, int64_t hi) {
  if (!j.is_number_integer()) bad(where(path) + " must be an integer, got " + type_name(j));
  if (j.is_number_unsigned()) {
    const uint64_t u = j.get<uint64_t>();
    if (u > static_cast<uint64_t>(hi)) bad(where(path) + " is " + std::to_string(u) + ", above the allowed " + std::to_string(hi));
    return static_cast<int64_t>(u);
  }
  const int64_t v = j.get<int64_t>();
  if (v < lo || v > hi) {
    bad(where(path) + " is " + std::to_string(v) + ", outside the allowed range " + std::to_string(lo) + ".." +
        std::to_string(hi));
  }
  return v;
}

int32_t index(const json& j, const std::string& path) {
  return static_cast<int32_t>(integer(j, path, 0, std::numeric_limits<int32_t>::max()));
}

Vec3 vec3(const json& j, const std::string& path) {
  if (!j.is_array() || j.size() != 3) bad(where(path) + " must be an array of 3 numbers");
  return {number(j[0], item(path, 0)), number(j[1], item(path, 1)), number(j[2], item(path, 2))};
}

std::string text(const json& j, const std::string& path) {
  if (!j.is_string()) bad(where(path) + " must be a string, got " + type_name(j));
  return j.get<std::string>();
}

GeomId geom_id(const json& j, const std::string& path) {
  auto id = GeomId::from_hex(text(j, path));
  if (!id) bad(where(path) + ": " + id.error().message);
  return *id;
}

DeformationModel deformation_model(const json& j, const std::string& path) {
  auto model = parse_deformation_model(text(j, path));
  if (!model) bad(where(path) + ": " + model.error().message);
  return *model;
}

SurfacePoint surface_point(const json& obj, const std::string& path, std::string_view face_key) {
  SurfacePoint p;
  p.face = index(require(obj, face_key, path), join(path, face_key));
  if (const json* s = find(obj, "subface")) p.subface = index(*s, join(path, "subface"));
  p.u = number(require(obj, "u", path), join(path, "u"));
  p.v = number(require(obj, "v", path), join(path, "v"));
  if (p.u < 0.0 || p.u > 1.0 || p.v < 0.0 || p.v > 1.0) {
    bad(where(path) + " has (u, v) = (" + describe_number(p.u) + ", " + describe_number(p.v) +
        "); both must lie in [0, 1]");
  }
  return p;
}

// The parser's own errors are the client's: invalid JSON. Everything else as `capture` says.
template <class Fn>
auto decoding(Fn&& fn) {
  return capture(
      [&] {
        try {
          return fn();
        } catch (const json::exception& e) {
          fail(ErrorCode::kInvalidArgument, std::string("invalid JSON: ") + e.what());
        }
      },
      "decoding the body");
}

void write_geometry_fields(JsonOut& out, const ControlMesh& mesh, const Material& material) {
  out.raw("\"vertices\":").array(mesh.positions(), [&](const Vec3& p) { out.vec3(p); });
  out.raw(",\"faces\":[");
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    if (f) out.raw(",");
    out.raw("[");
    auto face = mesh.face(f);
    for (size_t k = 0; k < face.size(); ++k) {
      if (k) out.raw(",");
      out.integer(face[k]);
    }
    out.raw("]");
  }
  out.raw("],\"material\":{\"youngs_modulus\":").number(material.youngs_modulus);
  out.raw(",\"poisson_ratio\":").number(material.poisson_ratio);
  out.raw(",\"thickness\":").number(material.thickness).raw("}");
  out.raw(",\"boundary\":").string(boundary_name(mesh.boundary()));
  if (!mesh.creases().empty()) {
    out.raw(",\"creases\":").array(mesh.creases(), [&](const Crease& c) {
      out.raw("{\"vertices\":[").integer(c.v0).raw(",").integer(c.v1).raw("],\"sharpness\":");
      out.number(static_cast<double>(c.sharpness)).raw("}");
    });
  }
  if (!mesh.corners().empty()) {
    out.raw(",\"corners\":").array(mesh.corners(), [&](const Corner& c) {
      out.raw("{\"vertex\":").integer(c.vertex).raw(",\"sharpness\":");
      out.number(static_cast<double>(c.sharpness)).raw("}");
    });
  }
}

float sharpness(const json& j, const std::string& path) {
  const double s = number(j, path);
  if (s < 0.0 || s > static_cast<double>(std::numeric_limits<float>::max())) {
    bad(where(path) + " must be a sharpness >= 0, got " + describe_number(s));
  }
  return static_cast<float>(s);
}

GeometryInfo geometry_info(const json& j, const std::string& path) {
  object(j, path);
  GeometryInfo info;
  info.id = geom_id(require(j, "geom_id", path), join(path, "geom_id"));
  if (const json* ns = find(j, "namespace")) info.name_space = text(*ns, join(path, "namespace"));
  info.vertices = index(require(j, "vertices", path), join(path, "vertices"));
  info.faces = index(require(j, "faces", path), join(path, "faces"));
  auto status = parse_geometry_status(text(require(j, "status", path), join(path, "status")));
  if (!status) bad(where(join(path, "status")) + ": " + status.error().message);
  info.status = *status;
  info.results = static_cast<uint32_t>(
      integer(require(j, "results", path), join(path, "results"), 0, std::numeric_limits<uint32_t>::max()));
  if (const json* p = find(j, "progress")) info.progress = number(*p, join(path, "progress"));
  if (const json* e = find(j, "error")) info.error = text(*e, join(path, "error"));
  return info;
}

void write_geometry_info(JsonOut& out, const GeometryInfo& info) {
  out.raw("{\"geom_id\":").string(info.id.hex());
  out.raw(",\"namespace\":").string(info.name_space);
  out.raw(",\"vertices\":").integer(info.vertices);
  out.raw(",\"faces\":").integer(info.faces);
  out.raw(",\"status\":").string(to_string(info.status));
  out.raw(",\"results\":").integer(info.results);
  out.raw(",\"progress\":").number(info.progress);
  if (!info.error.empty()) out.raw(",\"error\":").string(info.error);
  out.raw("}");
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Errors

std::string encode_error_json(const Error& error) { return encode_error_json(to_string(error.code), error.message); }

std::string encode_error_json(std::string_view code, std::string_view message) {
  JsonOut out;
  out.raw("{\"error\":").string(code).raw(",\"message\":").string(message).raw("}");
  return out.take();
}

Error decode_error_json(std::string_view body, int http_status) {
  Error error{error_code_for_status(http_status), ""};
  try {
    if (body.size() <= 1 << 20) {
      check_depth(body);
      json j = json::parse(body.begin(), body.end(), nullptr, /*allow_exceptions=*/false);
      if (j.is_object()) {
        if (const json* m = find(j, "message"); m && m->is_string()) error.message = m->get<std::string>();
        if (const json* c = find(j, "error"); c && c->is_string()) {
          const std::string code = c->get<std::string>();
          for (int k = 0; k <= static_cast<int>(ErrorCode::kGone); ++k) {
            if (to_string(static_cast<ErrorCode>(k)) == code) error.code = static_cast<ErrorCode>(k);
          }
        }
      }
    }
  } catch (const std::exception&) {
    // fall through to the raw body
  }
  if (error.message.empty()) {
    std::string raw(body.substr(0, 200));
    error.message = "HTTP " + std::to_string(http_status) + (raw.empty() ? "" : ": " + raw);
  }
  if (error.code == ErrorCode::kOk) error.code = ErrorCode::kInternal;
  return error;
}

// ---------------------------------------------------------------------------------------------
// Geometry

std::string encode_geometry_json(const ControlMesh& mesh, const Material& material) {
  JsonOut out;
  out.raw("{");
  write_geometry_fields(out, mesh, material);
  out.raw("}");
  return out.take();
}

std::string encode_geometry_json(const ControlMesh& mesh, const Material& material, const GeomId& id,
                                 std::string_view name_space) {
  JsonOut out;
  out.raw("{\"geom_id\":").string(id.hex()).raw(",\"namespace\":").string(name_space).raw(",");
  write_geometry_fields(out, mesh, material);
  out.raw("}");
  return out.take();
}

Result<Geometry> decode_geometry_json(std::string_view body) {
  return decoding([&]() -> Geometry {
    const json root = parse(body);
    object(root, "");
    known_keys(root, {"vertices", "faces", "material", "boundary", "creases", "corners", "geom_id", "namespace"}, "");
    Geometry g;

    const json& verts = array(require(root, "vertices", ""), "vertices");
    const json& faces = array(require(root, "faces", ""), "faces");
    if (verts.empty()) bad("the mesh is empty: 'vertices' has no control points");
    if (faces.empty()) bad("the mesh is empty: 'faces' has no faces");
    if (verts.size() > static_cast<size_t>(std::numeric_limits<int32_t>::max())) bad("too many vertices");
    const auto n = static_cast<int32_t>(verts.size());

    std::vector<Vec3> positions;
    positions.reserve(verts.size());
    for (size_t i = 0; i < verts.size(); ++i) positions.push_back(vec3(verts[i], item("vertices", i)));

    std::vector<int32_t> sizes, indices;
    sizes.reserve(faces.size());
    for (size_t f = 0; f < faces.size(); ++f) {
      const std::string path = item("faces", f);
      const json& face = array(faces[f], path);
      if (face.size() < 3) {
        bad("face " + std::to_string(f) + " has " + std::to_string(face.size()) +
            " control points; a face needs at least 3");
      }
      if (face.size() > static_cast<size_t>(kMaxFaceSize)) {
        bad("face " + std::to_string(f) + " has " + std::to_string(face.size()) + " control points; at most " +
            std::to_string(kMaxFaceSize) + " are supported");
      }
      if (indices.size() + face.size() > static_cast<size_t>(std::numeric_limits<int32_t>::max())) {
        bad("too many face corners");
      }
      for (size_t k = 0; k < face.size(); ++k) {
        const int32_t v = index(face[k], item(path, k));
        if (v >= n) {
          bad("face " + std::to_string(f) + " refers to control point " + std::to_string(v) + ", but there are only " +
              std::to_string(n) + " (indices are 0-based)");
        }
        indices.push_back(v);
      }
      sizes.push_back(static_cast<int32_t>(face.size()));
    }
    g.mesh = ControlMesh(std::move(positions), sizes, std::move(indices));

    const json& mat = object(require(root, "material", ""), "material");
    known_keys(mat, {"youngs_modulus", "poisson_ratio", "thickness"}, "material");
    g.material.youngs_modulus = number(require(mat, "youngs_modulus", "material"), "material.youngs_modulus");
    g.material.poisson_ratio = number(require(mat, "poisson_ratio", "material"), "material.poisson_ratio");
    g.material.thickness = number(require(mat, "thickness", "material"), "material.thickness");

    if (const json* b = find(root, "boundary")) {
      const std::string mode = text(*b, "boundary");
      if (mode == "edge_and_corner") g.mesh.set_boundary(BoundaryMode::kEdgeAndCorner);
      else if (mode == "none") g.mesh.set_boundary(BoundaryMode::kNone);
      else bad("'boundary' must be \"edge_and_corner\" or \"none\"");
    }
    if (const json* creases = find(root, "creases")) {
      array(*creases, "creases");
      for (size_t i = 0; i < creases->size(); ++i) {
        const std::string path = item("creases", i);
        const json& c = object((*creases)[i], path);
        known_keys(c, {"vertices", "sharpness"}, path);
        const json& ends = require(c, "vertices", path);
        if (!ends.is_array() || ends.size() != 2) bad(where(join(path, "vertices")) + " must be an array of 2 indices");
        Crease crease;
        crease.v0 = index(ends[0], item(join(path, "vertices"), 0));
        crease.v1 = index(ends[1], item(join(path, "vertices"), 1));
        if (crease.v0 >= n || crease.v1 >= n) bad(where(path) + " refers to a control point that does not exist");
        crease.sharpness = sharpness(require(c, "sharpness", path), join(path, "sharpness"));
        g.mesh.creases().push_back(crease);
      }
    }
    if (const json* corners = find(root, "corners")) {
      array(*corners, "corners");
      for (size_t i = 0; i < corners->size(); ++i) {
        const std::string path = item("corners", i);
        const json& c = object((*corners)[i], path);
        known_keys(c, {"vertex", "sharpness"}, path);
        Corner corner;
        corner.vertex = index(require(c, "vertex", path), join(path, "vertex"));
        if (corner.vertex >= n) bad(where(path) + " refers to a control point that does not exist");
        corner.sharpness = sharpness(require(c, "sharpness", path), join(path, "sharpness"));
        g.mesh.corners().push_back(corner);
      }
    }
    if (const json* ns = find(root, "namespace")) g.name_space = text(*ns, "namespace");
    if (const json* id = find(root, "geom_id")) geom_id(*id, "geom_id");  // must be well-formed if present
    return g;
  });
}

std::string encode_upload_response_json(const GeomId& id, GeometryStatus status) {
  JsonOut out;
  out.raw("{\"geom_id\":").string(id.hex()).raw(",\"status\":").string(to_string(status)).raw("}");
  return out.take();
}

Result<UploadResult> decode_upload_response_json(std::string_view body, bool created) {
  return decoding([&]() -> UploadResult {
    const json root = parse(body);
    object(root, "");
    UploadResult r;
    r.id = geom_id(require(root, "geom_id", ""), "geom_id");
    r.created = created;
    if (const json* s = find(root, "status")) {
      auto status = parse_geometry_status(text(*s, "status"));
      if (!status) bad("'status': " + status.error().message);
      r.status = *status;
    }
    return r;
  });
}

// ---------------------------------------------------------------------------------------------
// Deformation requests

std::string encode_request_json(const DeformationRequest& request) {
  JsonOut out;
  out.raw("{\"vertex_constraints\":").array(request.vertex_constraints, [&](const VertexConstraint& c) {
    out.raw("{\"index\":").integer(c.index).raw(",\"mask\":").integer(c.mask);
    out.raw(",\"displacement\":").vec3(c.displacement).raw("}");
  });
  out.raw(",\"lagrange_constraints\":").array(request.lagrange_constraints, [&](const LagrangeConstraint& c) {
    out.raw("{\"indices\":").integers(c.indices);
    out.raw(",\"coefficients\":").array(c.coefficients, [&](const Vec3& k) { out.vec3(k); });
    out.raw(",\"values\":").vec3(c.values).raw("}");
  });
  out.raw(",\"forces\":").array(request.forces, [&](const PointForce& f) {
    out.raw("{\"index\":").integer(f.index).raw(",\"force\":").vec3(f.force).raw("}");
  });
  auto point = [&](const SurfacePoint& p) {
    out.raw("\"face\":").integer(p.face).raw(",\"subface\":").integer(p.subface);
    out.raw(",\"u\":").number(p.u).raw(",\"v\":").number(p.v);
  };
  if (!request.limit_constraints.empty()) {
    out.raw(",\"limit_constraints\":").array(request.limit_constraints, [&](const LimitConstraint& c) {
      out.raw("{");
      point(c.point);
      out.raw(",\"displacement\":").vec3(c.displacement);
      if (c.du_displacement) out.raw(",\"du_displacement\":").vec3(*c.du_displacement);
      if (c.dv_displacement) out.raw(",\"dv_displacement\":").vec3(*c.dv_displacement);
      out.raw("}");
    });
  }
  if (!request.surface_forces.empty()) {
    out.raw(",\"surface_forces\":").array(request.surface_forces, [&](const SurfaceForce& f) {
      out.raw("{");
      point(f.point);
      out.raw(",\"force\":").vec3(f.force).raw("}");
    });
  }
  if (!request.surface_load.isZero(0.0)) out.raw(",\"surface_load\":").vec3(request.surface_load);
  if (request.pressure != 0.0) out.raw(",\"pressure\":").number(request.pressure);
  if (request.model == DeformationModel::kNonlinear) out.raw(",\"model\":\"nonlinear\"");
  out.raw("}");
  return out.take();
}

Result<DeformationRequest> decode_request_json(std::string_view body) {
  return decoding([&]() -> DeformationRequest {
    const json root = parse(body);
    object(root, "");
    known_keys(root,
               {"vertex_constraints", "lagrange_constraints", "forces", "limit_constraints", "surface_forces",
                "surface_load", "pressure", "model"},
               "");
    DeformationRequest r;
    if (const json* list = find(root, "vertex_constraints")) {
      array(*list, "vertex_constraints");
      r.vertex_constraints.reserve(list->size());
      for (size_t i = 0; i < list->size(); ++i) {
        const std::string path = item("vertex_constraints", i);
        const json& c = object((*list)[i], path);
        known_keys(c, {"index", "mask", "displacement"}, path);
        VertexConstraint vc;
        vc.index = index(require(c, "index", path), join(path, "index"));
        if (const json* m = find(c, "mask")) {
          vc.mask = static_cast<uint32_t>(integer(*m, join(path, "mask"), 0, std::numeric_limits<uint32_t>::max()));
          if (vc.mask == 0 || vc.mask > 7) {
            bad(where(join(path, "mask")) + " is " + std::to_string(vc.mask) +
                "; a mask is 1..7 (bits 1 = x, 2 = y, 4 = z)");
          }
        }
        if (const json* d = find(c, "displacement")) vc.displacement = vec3(*d, join(path, "displacement"));
        r.vertex_constraints.push_back(vc);
      }
    }
    if (const json* list = find(root, "lagrange_constraints")) {
      array(*list, "lagrange_constraints");
      r.lagrange_constraints.reserve(list->size());
      for (size_t i = 0; i < list->size(); ++i) {
        const std::string path = item("lagrange_constraints", i);
        const json& c = object((*list)[i], path);
        known_keys(c, {"indices", "coefficients", "values"}, path);
        LagrangeConstraint lc;
        const json& idx = array(require(c, "indices", path), join(path, "indices"));
        const json& coef = array(require(c, "coefficients", path), join(path, "coefficients"));
        if (idx.size() != coef.size()) {
          bad(where(path) + " has " + std::to_string(idx.size()) + " indices but " + std::to_string(coef.size()) +
              " coefficient triples; they must match");
        }
        lc.indices.reserve(idx.size());
        lc.coefficients.reserve(coef.size());
        for (size_t k = 0; k < idx.size(); ++k) lc.indices.push_back(index(idx[k], item(join(path, "indices"), k)));
        for (size_t k = 0; k < coef.size(); ++k) {
          lc.coefficients.push_back(vec3(coef[k], item(join(path, "coefficients"), k)));
        }
        if (const json* v = find(c, "values")) lc.values = vec3(*v, join(path, "values"));
        // No terms and zero values: says nothing, dropped (as in the binary decoder).
        if (!lc.indices.empty() || lc.values != Vec3::Zero()) r.lagrange_constraints.push_back(std::move(lc));
      }
    }
    if (const json* list = find(root, "forces")) {
      array(*list, "forces");
      r.forces.reserve(list->size());
      for (size_t i = 0; i < list->size(); ++i) {
        const std::string path = item("forces", i);
        const json& c = object((*list)[i], path);
        known_keys(c, {"index", "force"}, path);
        PointForce f;
        f.index = index(require(c, "index", path), join(path, "index"));
        f.force = vec3(require(c, "force", path), join(path, "force"));
        r.forces.push_back(f);
      }
    }
    if (const json* list = find(root, "limit_constraints")) {
      array(*list, "limit_constraints");
      r.limit_constraints.reserve(list->size());
      for (size_t i = 0; i < list->size(); ++i) {
        const std::string path = item("limit_constraints", i);
        const json& c = object((*list)[i], path);
        known_keys(c, {"face", "subface", "u", "v", "displacement", "du_displacement", "dv_displacement"}, path);
        LimitConstraint lc;
        lc.point = surface_point(c, path, "face");
        if (const json* d = find(c, "displacement")) lc.displacement = vec3(*d, join(path, "displacement"));
        if (const json* d = find(c, "du_displacement")) lc.du_displacement = vec3(*d, join(path, "du_displacement"));
        if (const json* d = find(c, "dv_displacement")) lc.dv_displacement = vec3(*d, join(path, "dv_displacement"));
        r.limit_constraints.push_back(lc);
      }
    }
    if (const json* list = find(root, "surface_forces")) {
      array(*list, "surface_forces");
      r.surface_forces.reserve(list->size());
      for (size_t i = 0; i < list->size(); ++i) {
        const std::string path = item("surface_forces", i);
        const json& c = object((*list)[i], path);
        known_keys(c, {"face", "subface", "u", "v", "force"}, path);
        SurfaceForce f;
        f.point = surface_point(c, path, "face");
        f.force = vec3(require(c, "force", path), join(path, "force"));
        r.surface_forces.push_back(f);
      }
    }
    if (const json* q = find(root, "surface_load")) r.surface_load = vec3(*q, "surface_load");
    if (const json* p = find(root, "pressure")) r.pressure = number(*p, "pressure");
    if (const json* m = find(root, "model")) r.model = deformation_model(*m, "model");
    return r;
  });
}

// ---------------------------------------------------------------------------------------------
// Results

std::string encode_result_json(const DeformationResult& result) {
  JsonOut out;
  out.raw("{\"res_id\":").integer(result.res_id).raw(",\"positions\":");
  out.array(result.positions, [&](const Vec3& p) { out.vec3(p); });
  if (result.model == DeformationModel::kNonlinear) {
    out.raw(",\"model\":\"nonlinear\",\"iterations\":").integer(result.iterations);
    out.raw(",\"residual\":").number(result.residual);
  }
  out.raw("}");
  return out.take();
}

Result<DeformationResult> decode_result_json(std::string_view body, std::optional<int32_t> expected_vertices) {
  return decoding([&]() -> DeformationResult {
    const json root = parse(body);
    object(root, "");
    DeformationResult r;
    r.res_id = static_cast<uint32_t>(
        integer(require(root, "res_id", ""), "res_id", 0, std::numeric_limits<uint32_t>::max()));
    const json& pos = array(require(root, "positions", ""), "positions");
    if (expected_vertices && pos.size() != static_cast<size_t>(*expected_vertices)) {
      bad("the result has " + std::to_string(pos.size()) + " control points, but the geometry has " +
          std::to_string(*expected_vertices));
    }
    r.positions.reserve(pos.size());
    for (size_t i = 0; i < pos.size(); ++i) r.positions.push_back(vec3(pos[i], item("positions", i)));
    if (const json* m = find(root, "model")) r.model = deformation_model(*m, "model");
    if (const json* k = find(root, "iterations")) {
      r.iterations = static_cast<int32_t>(integer(*k, "iterations", 0, std::numeric_limits<int32_t>::max()));
    }
    if (const json* q = find(root, "residual")) r.residual = number(*q, "residual");
    return r;
  });
}

std::string encode_result_ids_json(const std::vector<uint32_t>& ids) {
  JsonOut out;
  out.raw("{\"res_ids\":").array(ids, [&](uint32_t id) { out.integer(id); }).raw("}");
  return out.take();
}

Result<std::vector<uint32_t>> decode_result_ids_json(std::string_view body) {
  return decoding([&]() -> std::vector<uint32_t> {
    const json root = parse(body);
    object(root, "");
    const json& ids = array(require(root, "res_ids", ""), "res_ids");
    std::vector<uint32_t> out;
    out.reserve(ids.size());
    for (size_t i = 0; i < ids.size(); ++i) {
      out.push_back(static_cast<uint32_t>(integer(ids[i], item("res_ids", i), 0, std::numeric_limits<uint32_t>::max())));
    }
    return out;
  });
}

// ---------------------------------------------------------------------------------------------
// Limit combinations

std::string encode_limit_comb_json(const LimitComb& comb) {
  JsonOut out;
  out.raw("{\"face\":").integer(comb.point.face).raw(",\"subface\":").integer(comb.point.subface);
  out.raw(",\"u\":").number(comb.point.u).raw(",\"v\":").number(comb.point.v);
  out.raw(",\"indices\":").integers(comb.indices);
  out.raw(",\"position\":").numbers(comb.position);
  out.raw(",\"du\":").numbers(comb.du);
  out.raw(",\"dv\":").numbers(comb.dv).raw("}");
  return out.take();
}

Result<LimitComb> decode_limit_comb_json(std::string_view body) {
  return decoding([&]() -> LimitComb {
    const json root = parse(body);
    object(root, "");
    LimitComb c;
    c.point = surface_point(root, "", "face");
    const json& idx = array(require(root, "indices", ""), "indices");
    for (size_t i = 0; i < idx.size(); ++i) c.indices.push_back(index(idx[i], item("indices", i)));
    for (auto [key, out] : {std::pair{"position", &c.position}, std::pair{"du", &c.du}, std::pair{"dv", &c.dv}}) {
      const json& w = array(require(root, key, ""), key);
      if (w.size() != idx.size()) bad(std::string("'") + key + "' must have one weight per index");
      for (size_t i = 0; i < w.size(); ++i) out->push_back(number(w[i], item(key, i)));
    }
    return c;
  });
}

// ---------------------------------------------------------------------------------------------
// Holds (PROTOCOL.md version 2)

std::string encode_result_json(const DeformationResult& result, const HoldVersions& holds) {
  JsonOut out;
  out.raw("{\"res_id\":").integer(result.res_id).raw(",\"positions\":");
  out.array(result.positions, [&](const Vec3& p) { out.vec3(p); });
  if (result.model == DeformationModel::kNonlinear) {  // as in the layout without holds
    out.raw(",\"model\":\"nonlinear\",\"iterations\":").integer(result.iterations);
    out.raw(",\"residual\":").number(result.residual);
  }
  out.raw(",\"holds\":{");
  for (size_t i = 0; i < holds.size(); ++i) {
    if (i) out.raw(",");
    out.key(holds[i].first).integer(static_cast<int64_t>(holds[i].second));
  }
  out.raw("}}");
  return out.take();
}

Result<HeldResult> decode_held_result_json(std::string_view body, std::optional<int32_t> expected_vertices) {
  auto result = decode_result_json(body, expected_vertices);
  if (!result) return result.error();
  return decoding([&]() -> HeldResult {
    HeldResult r{std::move(*result), std::nullopt};
    const json root = parse(body);
    if (const json* h = find(root, "holds")) {
      object(*h, "holds");
      HoldVersions versions;
      for (auto it = h->begin(); it != h->end(); ++it) {
        versions.emplace_back(it.key(), static_cast<uint64_t>(integer(it.value(), join("holds", it.key()), 0,
                                                                      std::numeric_limits<int64_t>::max())));
      }
      r.holds = std::move(versions);
    }
    return r;
  });
}

std::string encode_hold_accepted_json(std::string_view hold_id, uint64_t version) {
  JsonOut out;
  out.raw("{").key("hold_id").string(hold_id).raw(",").key("version").integer(static_cast<int64_t>(version)).raw("}");
  return out.take();
}

namespace {

HoldInfo hold_info(const json& j, const std::string& path, bool with_expiry) {
  object(j, path);
  HoldInfo h;
  h.hold_id = text(require(j, "hold_id", path), join(path, "hold_id"));
  h.version = static_cast<uint64_t>(
      integer(require(j, "version", path), join(path, "version"), 0, std::numeric_limits<int64_t>::max()));
  if (with_expiry) h.expires_in = number(require(j, "expires_in", path), join(path, "expires_in"));
  return h;
}

void write_hold_info(JsonOut& out, const HoldInfo& h) {
  out.key("hold_id").string(h.hold_id).raw(",").key("version").integer(static_cast<int64_t>(h.version));
  out.raw(",").key("expires_in").number(h.expires_in);
}

}  // namespace

Result<HoldInfo> decode_hold_accepted_json(std::string_view body) {
  return decoding([&]() -> HoldInfo { return hold_info(parse(body), "", false); });
}

std::string encode_hold_list_json(const HoldList& list) {
  JsonOut out;
  out.raw("{\"holds\":").array(list.holds, [&](const HoldInfo& h) {
    out.raw("{");
    write_hold_info(out, h);
    out.raw("}");
  });
  out.raw(",\"res_id\":").integer(list.res_id).raw(",\"state\":").string(to_string(list.state));
  out.raw(",\"message\":").string(list.message).raw("}");
  return out.take();
}

Result<HoldList> decode_hold_list_json(std::string_view body) {
  return decoding([&]() -> HoldList {
    const json root = parse(body);
    object(root, "");
    HoldList list;
    const json& holds = array(require(root, "holds", ""), "holds");
    for (size_t i = 0; i < holds.size(); ++i) list.holds.push_back(hold_info(holds[i], item("holds", i), true));
    list.res_id = static_cast<uint32_t>(
        integer(require(root, "res_id", ""), "res_id", 0, std::numeric_limits<uint32_t>::max()));
    auto state = parse_hold_state(text(require(root, "state", ""), "state"));
    if (!state) throw Exception(state.error());
    list.state = *state;
    if (const json* m = find(root, "message")) list.message = text(*m, "message");
    return list;
  });
}

std::string encode_hold_json(const HoldDetail& hold) {
  JsonOut out;
  out.raw("{");
  write_hold_info(out, hold.info);
  out.raw(",\"request\":").raw(encode_request_json(hold.request)).raw("}");
  return out.take();
}

Result<HoldDetail> decode_hold_json(std::string_view body) {
  return decoding([&]() -> HoldDetail {
    const json root = parse(body);
    HoldDetail d;
    d.info = hold_info(root, "", true);
    auto request = decode_request_json(object(require(root, "request", ""), "request").dump());
    if (!request) throw Exception(request.error().code, "'request': " + request.error().message);
    d.request = std::move(*request);
    return d;
  });
}

// ---------------------------------------------------------------------------------------------
// Stresses (extension)

namespace {

void write_stress_sample(JsonOut& out, const StressSample& s) {
  out.raw("{\"face\":").integer(s.point.face).raw(",\"subface\":").integer(s.point.subface);
  out.raw(",\"u\":").number(s.point.u).raw(",\"v\":").number(s.point.v);
  out.raw(",\"position\":").vec3(s.position);
  out.raw(",\"membrane_force\":").vec3(s.membrane_force).raw(",\"bending_moment\":").vec3(s.bending_moment);
  out.raw(",\"von_mises_top\":").number(s.von_mises_top).raw(",\"von_mises_bottom\":").number(s.von_mises_bottom);
  out.raw(",\"von_mises\":").number(s.von_mises()).raw("}");
}

StressSample stress_sample(const json& j, const std::string& path) {
  object(j, path);
  StressSample s;
  s.point = surface_point(j, path, "face");
  s.position = vec3(require(j, "position", path), join(path, "position"));
  s.membrane_force = vec3(require(j, "membrane_force", path), join(path, "membrane_force"));
  s.bending_moment = vec3(require(j, "bending_moment", path), join(path, "bending_moment"));
  s.von_mises_top = number(require(j, "von_mises_top", path), join(path, "von_mises_top"));
  s.von_mises_bottom = number(require(j, "von_mises_bottom", path), join(path, "von_mises_bottom"));
  return s;
}

}  // namespace

std::string encode_stress_query_json(const StressQuery& query) {
  JsonOut out;
  out.raw("{\"yield_strength\":").number(query.yield_strength);
  if (query.level > 0) {
    out.raw(",\"level\":").integer(query.level);
  } else {
    out.raw(",\"points\":").array(query.points, [&](const SurfacePoint& p) {
      out.raw("{\"face\":").integer(p.face).raw(",\"subface\":").integer(p.subface);
      out.raw(",\"u\":").number(p.u).raw(",\"v\":").number(p.v).raw("}");
    });
  }
  out.raw("}");
  return out.take();
}

Result<StressQuery> decode_stress_query_json(std::string_view body) {
  return decoding([&]() -> StressQuery {
    const json root = parse(body);
    object(root, "");
    known_keys(root, {"level", "points", "yield_strength"}, "");
    StressQuery q;
    if (const json* y = find(root, "yield_strength")) {
      q.yield_strength = number(*y, "yield_strength");
      if (q.yield_strength < 0.0) bad("'yield_strength' must be >= 0 (Pa; 0 = unknown)");
    }
    if (const json* level = find(root, "level")) q.level = static_cast<int>(integer(*level, "level", 1, StressQuery::kMaxLevel));
    if (const json* points = find(root, "points")) {
      if (q.level) bad("give either 'level' or 'points', not both");
      array(*points, "points");
      if (points->size() > StressQuery::kMaxPoints) {
        bad("'points' has " + std::to_string(points->size()) + " entries, at most " +
            std::to_string(StressQuery::kMaxPoints) + " are served at once");
      }
      for (size_t i = 0; i < points->size(); ++i) {
        const std::string path = item("points", i);
        object((*points)[i], path);
        known_keys((*points)[i], {"face", "subface", "u", "v"}, path);
        q.points.push_back(surface_point((*points)[i], path, "face"));
      }
    } else if (!q.level) {
      bad("a stress query needs 'level' (1.." + std::to_string(StressQuery::kMaxLevel) + ") or 'points'");
    }
    return q;
  });
}

std::string encode_stress_field_json(const StressField& field, bool with_points) {
  JsonOut out;
  out.raw("{\"res_id\":").integer(field.res_id).raw(",\"yield_strength\":").number(field.yield_strength);
  out.raw(",\"exceeds_yield\":").raw(field.exceeds_yield ? "true" : "false");
  out.raw(",\"max\":");
  write_stress_sample(out, field.max);
  // Per point: parallel arrays (compact, and typed arrays for a browser).
  auto column = [&](const char* name, auto&& value) {
    out.raw(",\"").raw(name).raw("\":[");
    for (size_t i = 0; i < field.samples.size(); ++i) {
      if (i) out.raw(",");
      value(field.samples[i]);
    }
    out.raw("]");
  };
  if (with_points) {
    column("points", [&](const StressSample& s) {
      out.raw("[").integer(s.point.face).raw(",").integer(s.point.subface).raw(",").number(s.point.u).raw(",");
      out.number(s.point.v).raw("]");
    });
  }
  column("von_mises", [&](const StressSample& s) { out.number(s.von_mises()); });
  column("von_mises_top", [&](const StressSample& s) { out.number(s.von_mises_top); });
  column("von_mises_bottom", [&](const StressSample& s) { out.number(s.von_mises_bottom); });
  column("membrane_force", [&](const StressSample& s) { out.vec3(s.membrane_force); });
  column("bending_moment", [&](const StressSample& s) { out.vec3(s.bending_moment); });
  out.raw("}");
  return out.take();
}

Result<StressField> decode_stress_field_json(std::string_view body) {
  return decoding([&]() -> StressField {
    const json root = parse(body);
    object(root, "");
    StressField f;
    f.res_id = static_cast<uint32_t>(integer(require(root, "res_id", ""), "res_id", 0, std::numeric_limits<uint32_t>::max()));
    f.yield_strength = number(require(root, "yield_strength", ""), "yield_strength");
    const json& exceeds = require(root, "exceeds_yield", "");
    if (!exceeds.is_boolean()) bad("'exceeds_yield' must be a boolean");
    f.exceeds_yield = exceeds.get<bool>();
    f.max = stress_sample(require(root, "max", ""), "max");
    const json& top = array(require(root, "von_mises_top", ""), "von_mises_top");
    const json& bottom = array(require(root, "von_mises_bottom", ""), "von_mises_bottom");
    const json& membrane = array(require(root, "membrane_force", ""), "membrane_force");
    const json& bending = array(require(root, "bending_moment", ""), "bending_moment");
    const json* points = find(root, "points");
    const size_t n = top.size();
    if (bottom.size() != n || membrane.size() != n || bending.size() != n || (points && array(*points, "points").size() != n)) {
      bad("the per-point arrays of a stress answer must all have the same length");
    }
    f.samples.resize(n);
    for (size_t i = 0; i < n; ++i) {
      StressSample& s = f.samples[i];
      s.von_mises_top = number(top[i], item("von_mises_top", i));
      s.von_mises_bottom = number(bottom[i], item("von_mises_bottom", i));
      s.membrane_force = vec3(membrane[i], item("membrane_force", i));
      s.bending_moment = vec3(bending[i], item("bending_moment", i));
      if (points) {
        const json& p = (*points)[i];
        const std::string path = item("points", i);
        if (!p.is_array() || p.size() != 4) bad(where(path) + " must be [face, subface, u, v]");
        s.point = SurfacePoint{index(p[0], path), index(p[1], path), number(p[2], path), number(p[3], path)};
      }
    }
    return f;
  });
}

// ---------------------------------------------------------------------------------------------
// Geometry lists

std::string encode_geometry_info_json(const GeometryInfo& info) {
  JsonOut out;
  write_geometry_info(out, info);
  return out.take();
}

Result<GeometryInfo> decode_geometry_info_json(std::string_view body) {
  return decoding([&]() -> GeometryInfo { return geometry_info(parse(body), ""); });
}

std::string encode_geometry_list_json(const std::vector<GeometryInfo>& list) {
  JsonOut out;
  out.array(list, [&](const GeometryInfo& info) { write_geometry_info(out, info); });
  return out.take();
}

Result<std::vector<GeometryInfo>> decode_geometry_list_json(std::string_view body) {
  return decoding([&]() -> std::vector<GeometryInfo> {
    const json root = parse(body);
    array(root, "");
    std::vector<GeometryInfo> list;
    list.reserve(root.size());
    for (size_t i = 0; i < root.size(); ++i) list.push_back(geometry_info(root[i], item("", i)));
    return list;
  });
}

Result<GeometryStatus> parse_geometry_status(std::string_view name) {
  if (name == "precomputing") return GeometryStatus::kPrecomputing;
  if (name == "ready") return GeometryStatus::kReady;
  if (name == "failed") return GeometryStatus::kFailed;
  return Error{ErrorCode::kInvalidArgument,
               "unknown geometry status '" + std::string(name.substr(0, 40)) + "' (precomputing, ready, failed)"};
}

Result<DeformationModel> parse_deformation_model(std::string_view name) {
  if (name == "linear") return DeformationModel::kLinear;
  if (name == "nonlinear") return DeformationModel::kNonlinear;
  return Error{ErrorCode::kInvalidArgument,
               "unknown model '" + std::string(name.substr(0, 40)) + "'; the models are linear and nonlinear"};
}

}  // namespace softshell::wire
