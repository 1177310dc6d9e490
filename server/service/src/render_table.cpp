#include "softshell/service/render_table.h"

#include <charconv>
#include <cstring>
#include <limits>

#include "softshell/service/service.h"
#include "softshell/tessellation.h"

namespace softshell::service {

size_t RenderTable::bytes() const {
  return offsets.size() * 4 + indices.size() * 4 + (position.size() + du.size() + dv.size()) * 8 +
         quads.size() * sizeof(Quad) + triangles.size() * 4;
}

Result<RenderTable> render_table(const LimitEvaluator& evaluator, int level) {
  if (level < RenderTable::kMinLevel || level > RenderTable::kMaxLevel) {
    return Error{ErrorCode::kInvalidArgument, "render: level must be between " + std::to_string(RenderTable::kMinLevel) +
                                                  " and " + std::to_string(RenderTable::kMaxLevel) + ", got " +
                                                  std::to_string(level)};
  }
  auto tess = Tessellation::create(evaluator, level, 2 * RenderTable::kMaxQuads);
  if (!tess) return tess.error();
  return capture([&]() -> RenderTable {
    RenderTable t;
    t.level = level;
    t.control_points = evaluator.num_control_points();
    const auto& points = tess->vertex_points();
    t.vertices = static_cast<int32_t>(points.size());
    t.offsets.reserve(points.size() + 1);
    t.offsets.push_back(0);
    LimitStencil st;
    for (const SurfacePoint& p : points) {
      evaluator.stencil(p, st);  // the stencils Tessellation::limit_matrix is made of
      for (size_t k = 0; k < st.size(); ++k) {
        t.indices.push_back(static_cast<uint32_t>(st.indices[k]));
        t.position.push_back(st.position[k]);
        t.du.push_back(st.du[k]);
        t.dv.push_back(st.dv[k]);
      }
      if (t.indices.size() > std::numeric_limits<uint32_t>::max()) {
        fail(ErrorCode::kResourceExhausted, "render: the stencil table is too large; use a lower level");
      }
      t.offsets.push_back(static_cast<uint32_t>(t.indices.size()));
    }
    t.quads.reserve(tess->quads().size());
    for (const Tessellation::Quad& q : tess->quads()) {
      RenderTable::Quad out;
      for (int c = 0; c < 4; ++c) out.vertices[c] = static_cast<uint32_t>(q.vertices[static_cast<size_t>(c)]);
      out.root_face = static_cast<uint32_t>(q.root_face);
      out.subface = static_cast<uint32_t>(q.subface);
      out.path = static_cast<uint32_t>(q.path.bits);  // depth <= kMaxLevel: 12 bits
      out.depth = q.path.depth;
      out.rotation = q.rotation;
      t.quads.push_back(out);
    }
    t.triangles.reserve(3 * tess->triangles().size());
    for (const auto& tri : tess->triangles()) {
      for (int32_t v : tri) t.triangles.push_back(static_cast<uint32_t>(v));
    }
    return t;
  }, "building a render table");
}

Result<RenderTable> render_table(const Service& service, const GeomId& id, int level) {
  auto evaluator = service.limit_evaluator(id);
  if (!evaluator) return evaluator.error();
  return render_table(*evaluator, level);
}

namespace {

void put_u32(std::string& out, uint32_t v) {
  char b[4] = {static_cast<char>(v & 0xff), static_cast<char>((v >> 8) & 0xff), static_cast<char>((v >> 16) & 0xff),
               static_cast<char>((v >> 24) & 0xff)};
  out.append(b, 4);
}
void put_f32(std::string& out, double v) {
  const auto f = static_cast<float>(v);
  uint32_t bits = 0;
  std::memcpy(&bits, &f, 4);
  put_u32(out, bits);
}

template <class T>
void put_json_array(std::string& out, const char* name, const std::vector<T>& values, bool last = false) {
  out += '"';
  out += name;
  out += "\":[";
  char buf[32];
  for (size_t i = 0; i < values.size(); ++i) {
    if (i) out += ',';
    auto [end, ec] = std::to_chars(buf, buf + sizeof buf, values[i]);  // shortest round-trip form
    out.append(buf, end);
  }
  out += last ? "]" : "],";
}

}  // namespace

std::string encode_render_table_binary(const RenderTable& t) {
  std::string out;
  out.reserve(32 + t.offsets.size() * 4 + t.indices.size() * 16 + t.quads.size() * 32 + t.triangles.size() * 4);
  out.append("SSRT", 4);
  put_u32(out, 1);  // version
  put_u32(out, static_cast<uint32_t>(t.level));
  put_u32(out, static_cast<uint32_t>(t.control_points));
  put_u32(out, static_cast<uint32_t>(t.vertices));
  put_u32(out, static_cast<uint32_t>(t.quads.size()));
  put_u32(out, static_cast<uint32_t>(t.indices.size()));
  put_u32(out, 0);  // flags
  for (uint32_t o : t.offsets) put_u32(out, o);
  for (uint32_t i : t.indices) put_u32(out, i);
  for (double w : t.position) put_f32(out, w);
  for (double w : t.du) put_f32(out, w);
  for (double w : t.dv) put_f32(out, w);
  for (const RenderTable::Quad& q : t.quads) {
    for (uint32_t v : q.vertices) put_u32(out, v);
    put_u32(out, q.root_face);
    put_u32(out, q.subface);
    put_u32(out, q.path);
    put_u32(out, static_cast<uint32_t>(q.depth) | (static_cast<uint32_t>(q.rotation) << 8));
  }
  for (uint32_t v : t.triangles) put_u32(out, v);
  return out;
}

std::string encode_render_table_json(const RenderTable& t) {
  std::string out;
  out.reserve(64 + t.indices.size() * 70 + t.quads.size() * 60);
  out += "{\"level\":" + std::to_string(t.level) + ",\"control_points\":" + std::to_string(t.control_points) +
         ",\"vertices\":" + std::to_string(t.vertices) + ",\"stencils\":{";
  put_json_array(out, "offsets", t.offsets);
  put_json_array(out, "indices", t.indices);
  put_json_array(out, "position", t.position);
  put_json_array(out, "du", t.du);
  put_json_array(out, "dv", t.dv, true);
  out += "},\"quads\":{";
  std::vector<uint32_t> verts, root, sub, path, depth, rot;
  verts.reserve(4 * t.quads.size());
  for (const RenderTable::Quad& q : t.quads) {
    verts.insert(verts.end(), q.vertices, q.vertices + 4);
    root.push_back(q.root_face);
    sub.push_back(q.subface);
    path.push_back(q.path);
    depth.push_back(q.depth);
    rot.push_back(q.rotation);
  }
  put_json_array(out, "vertices", verts);
  put_json_array(out, "root_face", root);
  put_json_array(out, "subface", sub);
  put_json_array(out, "path", path);
  put_json_array(out, "depth", depth);
  put_json_array(out, "rotation", rot, true);
  out += "},";
  put_json_array(out, "triangles", t.triangles, true);
  out += '}';
  return out;
}

}  // namespace softshell::service
