// Binary layouts of PROTOCOL.md (little-endian u32 / f32).
#include <algorithm>
#include <limits>
#include <string>

#include "softshell/wire.h"
#include "wire_internal.h"

namespace softshell::wire {
namespace {

using internal::ByteReader;
using internal::ByteWriter;
using softshell::describe_number;
using internal::fits_f32;

[[noreturn]] void bad(const std::string& message) { fail(ErrorCode::kInvalidArgument, message); }

std::string bytes(uint64_t n) { return std::to_string(n) + (n == 1 ? " byte" : " bytes"); }

// Reads one f32 that must be finite; `what` names it for the message.
double finite_f32(ByteReader& in, const std::string& what) {
  const float f = in.f32();
  if (!std::isfinite(f)) bad(what + " is " + describe_number(f) + "; every number must be finite");
  return static_cast<double>(f);
}

Vec3 finite_vec3(ByteReader& in, const std::string& what) {
  Vec3 v;
  for (int a = 0; a < 3; ++a) v[a] = finite_f32(in, what);
  return v;
}

// Writes a double as f32, failing if it is not finite or overflows f32.
void put_f32(ByteWriter& out, double v, const char* what) {
  if (!fits_f32(v)) {
    bad(std::string(what) + " (" + describe_number(v) +
        ") is not representable as a 32-bit float; use the JSON format for it");
  }
  out.f32(static_cast<float>(v));
}

void put_vec3(ByteWriter& out, const Vec3& v, const char* what) {
  for (int a = 0; a < 3; ++a) put_f32(out, v[a], what);
}

// A control point index read as u32: indices above INT32_MAX cannot name a control point.
int32_t index_u32(ByteReader& in, const std::string& what) {
  const uint32_t i = in.u32();
  if (i > static_cast<uint32_t>(std::numeric_limits<int32_t>::max())) {
    bad(what + " is " + std::to_string(i) + ", which is out of range for any mesh");
  }
  return static_cast<int32_t>(i);
}

uint32_t checked_count(size_t n, const char* what) {
  if (n > std::numeric_limits<uint32_t>::max()) bad(std::string("too many ") + what + " for the binary layout");
  return static_cast<uint32_t>(n);
}

void check_consumed(const ByteReader& in, std::string_view body, const char* what) {
  if (in.remaining() != 0) {
    bad("the " + std::string(what) + " ends after " + bytes(in.position()) + ", but the body has " +
        bytes(body.size()) + " (" + bytes(in.remaining()) + " of trailing data)");
  }
}

template <class Fn>
auto decoding(Fn&& fn) {
  return capture(std::forward<Fn>(fn), "decoding the body");
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Geometry

bool geometry_fits_binary(const ControlMesh& mesh) {
  return mesh.all_quads() && !mesh.has_sharpness() && mesh.boundary() == BoundaryMode::kEdgeAndCorner;
}

bool geometry_is_float32_exact(const ControlMesh& mesh, const Material& material) {
  using internal::exact_f32;
  if (!exact_f32(material.youngs_modulus) || !exact_f32(material.poisson_ratio) || !exact_f32(material.thickness)) {
    return false;
  }
  for (const Vec3& p : mesh.positions()) {
    if (!exact_f32(p.x()) || !exact_f32(p.y()) || !exact_f32(p.z())) return false;
  }
  return true;
}

Result<std::string> encode_geometry_binary(const ControlMesh& mesh, const Material& material) {
  return decoding([&]() -> std::string {
    if (!mesh.all_quads()) bad("the binary geometry layout needs every face to be a quad; use the JSON format");
    if (mesh.has_sharpness()) bad("the binary geometry layout cannot carry crease or corner tags; use the JSON format");
    if (mesh.boundary() != BoundaryMode::kEdgeAndCorner) {
      bad("the binary geometry layout cannot carry boundary \"none\"; use the JSON format");
    }
    const size_t n = mesh.positions().size(), m = static_cast<size_t>(mesh.num_faces());
    ByteWriter out(20 + 12 * n + 16 * m);
    out.u32(checked_count(n, "control points"));
    out.u32(checked_count(m, "faces"));
    put_f32(out, material.youngs_modulus, "Young's modulus");
    put_f32(out, material.poisson_ratio, "Poisson's ratio");
    put_f32(out, material.thickness, "the thickness");
    for (const Vec3& p : mesh.positions()) put_vec3(out, p, "a control point coordinate");
    for (int32_t idx : mesh.face_indices()) {
      if (idx < 0) bad("a face has a negative control point index");
      out.u32(static_cast<uint32_t>(idx));
    }
    return out.take();
  });
}

Result<Geometry> decode_geometry_binary(std::string_view body) {
  return decoding([&]() -> Geometry {
    constexpr size_t kHeader = 20;
    if (body.size() < kHeader) {
      bad("a binary geometry starts with a 20-byte header (u32 n, u32 m, f32 E, f32 nu, f32 t), but the body has " +
          bytes(body.size()));
    }
    ByteReader in(body);
    const uint32_t n = in.u32(), m = in.u32();
    // Exact length before anything is allocated: 20 + 12 n + 16 m (no overflow in 64 bits).
    const uint64_t expected = kHeader + 12 * uint64_t{n} + 16 * uint64_t{m};
    if (expected != body.size()) {
      bad("a binary geometry with n = " + std::to_string(n) + " control points and m = " + std::to_string(m) +
          " quads is " + bytes(expected) + " long (20 + 12 n + 16 m), but the body has " + bytes(body.size()));
    }
    if (n == 0 || m == 0) bad("the mesh is empty (n = " + std::to_string(n) + ", m = " + std::to_string(m) + ")");
    if (n > static_cast<uint32_t>(std::numeric_limits<int32_t>::max()) ||
        uint64_t{m} * 4 > static_cast<uint64_t>(std::numeric_limits<int32_t>::max())) {
      bad("the mesh is too large (at most 2^31 - 1 control points and face corners)");
    }
    Geometry g;
    g.material.youngs_modulus = finite_f32(in, "Young's modulus");
    g.material.poisson_ratio = finite_f32(in, "Poisson's ratio");
    g.material.thickness = finite_f32(in, "the thickness");

    std::vector<Vec3> positions(n);
    for (uint32_t i = 0; i < n; ++i) positions[i] = finite_vec3(in, "a coordinate of control point " + std::to_string(i));

    std::vector<int32_t> indices(size_t{m} * 4);
    for (uint32_t f = 0; f < m; ++f) {
      for (int k = 0; k < 4; ++k) {
        const uint32_t idx = in.u32();
        if (idx >= n) {
          bad("face " + std::to_string(f) + " refers to control point " + std::to_string(idx) + ", but there are only " +
              std::to_string(n) + " (indices are 0-based)");
        }
        indices[size_t{f} * 4 + static_cast<size_t>(k)] = static_cast<int32_t>(idx);
      }
    }
    check_consumed(in, body, "geometry");
    g.mesh = ControlMesh(std::move(positions), std::vector<int32_t>(m, 4), std::move(indices));
    return g;
  });
}

std::string encode_upload_response_binary(const GeomId& id) {
  return std::string(reinterpret_cast<const char*>(id.bytes.data()), id.bytes.size());
}

Result<UploadResult> decode_upload_response_binary(std::string_view body, bool created) {
  if (body.size() != 16) {
    return Error{ErrorCode::kInvalidArgument,
                 "a binary upload response is the 16 id bytes, but the body has " + bytes(body.size())};
  }
  UploadResult r;
  std::memcpy(r.id.bytes.data(), body.data(), 16);
  r.created = created;
  r.status = GeometryStatus::kPrecomputing;
  return r;
}

// ---------------------------------------------------------------------------------------------
// Deformation requests

Result<std::string> encode_request_binary(const DeformationRequest& request) {
  return decoding([&]() -> std::string {
    if (!request.fits_binary_layout()) {
      bad("the request uses JSON-only fields (limit constraints, surface forces, surface load, pressure or the "
          "nonlinear model); use the JSON format");
    }
    ByteWriter out;
    out.u32(checked_count(request.vertex_constraints.size(), "vertex constraints"));
    out.u32(checked_count(request.lagrange_constraints.size(), "Lagrange constraints"));
    out.u32(checked_count(request.forces.size(), "forces"));
    for (const auto& c : request.vertex_constraints) put_vec3(out, c.displacement, "a vertex constraint displacement");
    for (const auto& c : request.vertex_constraints) {
      if (c.index < 0) bad("a vertex constraint has a negative index");
      out.u32(c.mask);
      out.u32(static_cast<uint32_t>(c.index));
    }
    for (const auto& c : request.lagrange_constraints) {
      if (c.indices.size() != c.coefficients.size()) {
        bad("a Lagrange constraint has " + std::to_string(c.indices.size()) + " indices but " +
            std::to_string(c.coefficients.size()) + " coefficient triples");
      }
      out.u32(checked_count(c.indices.size(), "Lagrange indices"));
      for (int32_t i : c.indices) {
        if (i < 0) bad("a Lagrange constraint has a negative index");
        out.u32(static_cast<uint32_t>(i));
      }
      for (const Vec3& k : c.coefficients) put_vec3(out, k, "a Lagrange coefficient");
      put_vec3(out, c.values, "a Lagrange value");
    }
    for (const auto& f : request.forces) put_vec3(out, f.force, "a force");
    for (const auto& f : request.forces) {
      if (f.index < 0) bad("a force has a negative index");
      out.u32(static_cast<uint32_t>(f.index));
    }
    return out.take();
  });
}

Result<DeformationRequest> decode_request_binary(std::string_view body) {
  return decoding([&]() -> DeformationRequest {
    if (body.size() < 12) {
      bad("a binary deformation request starts with three u32 counts (vertex constraints, Lagrange constraints, "
          "forces), but the body has " + bytes(body.size()));
    }
    ByteReader in(body);
    const uint32_t v = in.u32(), l = in.u32(), f = in.u32();
    // The smallest body these counts allow (every Lagrange constraint takes at least 16 bytes),
    // checked before anything is allocated.
    const uint64_t minimum = 12 + 20 * uint64_t{v} + 16 * uint64_t{l} + 16 * uint64_t{f};
    if (minimum > body.size()) {
      bad("a request with " + std::to_string(v) + " vertex constraints, " + std::to_string(l) +
          " Lagrange constraints and " + std::to_string(f) + " forces needs at least " + bytes(minimum) +
          ", but the body has " + bytes(body.size()));
    }
    DeformationRequest r;
    r.vertex_constraints.resize(v);
    for (uint32_t i = 0; i < v; ++i) {
      r.vertex_constraints[i].displacement = finite_vec3(in, "the displacement of vertex constraint " + std::to_string(i));
    }
    for (uint32_t i = 0; i < v; ++i) {
      auto& c = r.vertex_constraints[i];
      c.mask = in.u32();
      if (c.mask == 0 || c.mask > 7) {
        bad("vertex constraint " + std::to_string(i) + " has mask " + std::to_string(c.mask) +
            "; a mask is 1..7 (bits 1 = x, 2 = y, 4 = z)");
      }
      c.index = index_u32(in, "the index of vertex constraint " + std::to_string(i));
    }
    // A constraint with no terms and zero values says nothing (PROTOCOL.md drops such an
    // equation); it is dropped here, so padding a request with them costs neither memory nor
    // the size of what is stored and served again.
    r.lagrange_constraints.reserve(std::min<uint64_t>(l, in.remaining() / 16));
    for (uint32_t i = 0; i < l; ++i) {
      const uint32_t p = in.u32();
      // What must still follow: this constraint (16 p + 12) and the rest at their minimum sizes.
      const uint64_t rest = 16 * uint64_t{l - i - 1} + 16 * uint64_t{f};
      const uint64_t needed = 16 * uint64_t{p} + 12 + rest;
      if (needed > in.remaining()) {
        bad("Lagrange constraint " + std::to_string(i) + " claims " + std::to_string(p) +
            " control points, which needs " + bytes(16 * uint64_t{p} + 12) + " more (plus " + bytes(rest) +
            " for what follows), but only " + bytes(in.remaining()) + " remain");
      }
      LagrangeConstraint c;
      c.indices.resize(p);
      c.coefficients.resize(p);
      const std::string name = "Lagrange constraint " + std::to_string(i);
      for (uint32_t j = 0; j < p; ++j) c.indices[j] = index_u32(in, "an index of " + name);
      for (uint32_t j = 0; j < p; ++j) c.coefficients[j] = finite_vec3(in, "a coefficient of " + name);
      c.values = finite_vec3(in, "a value of " + name);
      if (p > 0 || c.values != Vec3::Zero()) r.lagrange_constraints.push_back(std::move(c));
    }
    if (in.remaining() < 16 * uint64_t{f}) {
      bad("the " + std::to_string(f) + " forces need " + bytes(16 * uint64_t{f}) + ", but only " +
          bytes(in.remaining()) + " remain");
    }
    r.forces.resize(f);
    for (uint32_t i = 0; i < f; ++i) r.forces[i].force = finite_vec3(in, "force " + std::to_string(i));
    for (uint32_t i = 0; i < f; ++i) r.forces[i].index = index_u32(in, "the index of force " + std::to_string(i));
    check_consumed(in, body, "request");
    return r;
  });
}

// ---------------------------------------------------------------------------------------------
// Results

Result<std::string> encode_result_binary(const DeformationResult& result) {
  return decoding([&]() -> std::string {
    ByteWriter out(4 + 12 * result.positions.size());
    out.u32(result.res_id);
    for (const Vec3& p : result.positions) put_vec3(out, p, "a deformed position");
    return out.take();
  });
}

Result<DeformationResult> decode_result_binary(std::string_view body, std::optional<int32_t> expected_vertices) {
  return decoding([&]() -> DeformationResult {
    if (body.size() < 4 || (body.size() - 4) % 12 != 0) {
      bad("a binary result is a u32 res_id followed by 12 bytes per control point, but the body has " +
          bytes(body.size()));
    }
    const size_t n = (body.size() - 4) / 12;
    if (expected_vertices && n != static_cast<size_t>(*expected_vertices)) {
      bad("the result has " + std::to_string(n) + " control points, but the geometry has " +
          std::to_string(*expected_vertices));
    }
    ByteReader in(body);
    DeformationResult r;
    r.res_id = in.u32();
    r.positions.resize(n);
    for (size_t i = 0; i < n; ++i) r.positions[i] = finite_vec3(in, "position " + std::to_string(i));
    return r;
  });
}

// ---------------------------------------------------------------------------------------------
// Limit combinations

Result<std::string> encode_limit_comb_binary(const LimitComb& comb) {
  return decoding([&]() -> std::string {
    const size_t p = comb.indices.size();
    if (comb.position.size() != p || comb.du.size() != p || comb.dv.size() != p) {
      bad("a limit combination needs as many weights of each kind as indices");
    }
    ByteWriter out(4 + 16 * p);
    out.u32(checked_count(p, "stencil entries"));
    for (int32_t i : comb.indices) out.u32(static_cast<uint32_t>(i));
    for (double w : comb.position) put_f32(out, w, "a position weight");
    for (double w : comb.du) put_f32(out, w, "a du weight");
    for (double w : comb.dv) put_f32(out, w, "a dv weight");
    return out.take();
  });
}

Result<LimitComb> decode_limit_comb_binary(std::string_view body, const SurfacePoint& point) {
  return decoding([&]() -> LimitComb {
    if (body.size() < 4) bad("a binary limit combination starts with a u32 count, but the body has " + bytes(body.size()));
    ByteReader in(body);
    const uint32_t p = in.u32();
    if (4 + 16 * uint64_t{p} != body.size()) {
      bad("a binary limit combination of " + std::to_string(p) + " control points is " + bytes(4 + 16 * uint64_t{p}) +
          " long, but the body has " + bytes(body.size()));
    }
    LimitComb c;
    c.point = point;
    c.indices.resize(p);
    for (auto& i : c.indices) i = index_u32(in, "a limit combination index");
    for (auto* weights : {&c.position, &c.du, &c.dv}) {
      weights->resize(p);
      for (auto& w : *weights) w = finite_f32(in, "a limit combination weight");
    }
    return c;
  });
}

}  // namespace softshell::wire
