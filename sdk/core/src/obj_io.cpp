#include "softshell/obj_io.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <cstring>
#include <map>
#include <system_error>

#include "softshell/mesh_validation.h"

namespace softshell {
namespace {

// A cursor over one logical OBJ line.
class LineCursor {
 public:
  explicit LineCursor(std::string_view line) : rest_(line) {}

  // Next whitespace-separated token, or empty at the end.
  std::string_view token() {
    skip_space();
    size_t end = 0;
    while (end < rest_.size() && !is_space(rest_[end])) ++end;
    std::string_view tok = rest_.substr(0, end);
    rest_.remove_prefix(end);
    return tok;
  }
  bool at_end() {
    skip_space();
    return rest_.empty();
  }

 private:
  static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }
  void skip_space() {
    while (!rest_.empty() && is_space(rest_.front())) rest_.remove_prefix(1);
  }
  std::string_view rest_;
};

bool parse_double(std::string_view s, double& out) {
  if (s.empty()) return false;
  if (s.front() == '+') s.remove_prefix(1);
  auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && ptr == s.data() + s.size();
}

bool parse_int64(std::string_view s, int64_t& out) {
  if (s.empty()) return false;
  if (s.front() == '+') s.remove_prefix(1);
  auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && ptr == s.data() + s.size();
}

std::string quoted(std::string_view s) {
  constexpr size_t kMax = 40;
  std::string out = "'";
  for (char c : s.substr(0, kMax)) out += (static_cast<unsigned char>(c) < 32 || c == 127) ? '?' : c;
  if (s.size() > kMax) out += "...";
  return out + "'";
}

class ObjParser {
 public:
  ObjParser(std::string_view source, const ObjReadOptions& options) : source_(source), options_(options) {}

  ControlMesh parse(std::string_view text) {
    size_t pos = 0;
    std::string joined;  // for lines continued with a backslash
    while (pos < text.size()) {
      size_t end = text.find('\n', pos);
      if (end == std::string_view::npos) end = text.size();
      std::string_view line = text.substr(pos, end - pos);
      ++line_number_;
      const int64_t first_line = line_number_;
      pos = end + 1;
      // Join continuation lines ("... \").
      auto continued = [](std::string_view l) {
        while (!l.empty() && (l.back() == '\r' || l.back() == ' ' || l.back() == '\t')) l.remove_suffix(1);
        return !l.empty() && l.back() == '\\';
      };
      if (continued(line)) {
        joined.clear();
        while (true) {
          std::string_view l = line;
          while (!l.empty() && (l.back() == '\r' || l.back() == ' ' || l.back() == '\t')) l.remove_suffix(1);
          if (!l.empty() && l.back() == '\\') {
            joined.append(l.substr(0, l.size() - 1));
            joined.push_back(' ');
            if (pos >= text.size()) break;
            end = text.find('\n', pos);
            if (end == std::string_view::npos) end = text.size();
            line = text.substr(pos, end - pos);
            ++line_number_;
            pos = end + 1;
          } else {
            joined.append(l);
            break;
          }
        }
        current_line_ = first_line;
        parse_line(joined);
      } else {
        current_line_ = first_line;
        parse_line(line);
      }
    }
    return finish();
  }

 private:
  [[noreturn]] void error(const std::string& what) const {
    fail(ErrorCode::kInvalidArgument, std::string(source_) + ":" + std::to_string(current_line_) + ": " + what);
  }

  void parse_line(std::string_view line) {
    if (size_t hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
    LineCursor cur(line);
    std::string_view keyword = cur.token();
    if (keyword.empty()) return;
    if (keyword == "v") {
      parse_vertex(cur);
    } else if (keyword == "f") {
      parse_face(cur);
    } else if (keyword == "t") {
      parse_tag(cur);
    } else if (keyword == "vt" || keyword == "vn" || keyword == "vp" || keyword == "o" || keyword == "g" ||
               keyword == "s" || keyword == "usemtl" || keyword == "mtllib" || keyword == "l" ||
               keyword == "p") {
      // Not geometry of the control mesh: ignored.
    } else {
      error("unknown OBJ statement " + quoted(keyword) +
            " (expected v, f, t, vt, vn, o, g, s, usemtl, mtllib or a # comment)");
    }
  }

  void parse_vertex(LineCursor& cur) {
    if (static_cast<int64_t>(positions_.size()) >= options_.max_vertices) {
      error("more than " + std::to_string(options_.max_vertices) + " vertices");
    }
    double xyz[3];
    for (double& c : xyz) {
      std::string_view tok = cur.token();
      if (tok.empty()) error("a vertex needs three coordinates: 'v x y z'");
      if (!parse_double(tok, c)) error("vertex coordinate " + quoted(tok) + " is not a number");
      if (!std::isfinite(c)) error("vertex coordinate " + quoted(tok) + " is not finite");
    }
    // Optional w or r g b: numbers that we accept and ignore.
    for (int extra = 0; !cur.at_end(); ++extra) {
      std::string_view tok = cur.token();
      double ignored = 0.0;
      if (extra >= 4 || !parse_double(tok, ignored)) error("unexpected " + quoted(tok) + " after the vertex coordinates");
    }
    positions_.emplace_back(xyz[0], xyz[1], xyz[2]);
    if (options_.validate) vertex_lines_.push_back(current_line_);
  }

  int32_t resolve_index(std::string_view tok, const char* what) {
    int64_t index = 0;
    if (!parse_int64(tok, index)) error(std::string(what) + " " + quoted(tok) + " is not an integer");
    const auto n = static_cast<int64_t>(positions_.size());
    if (index > 0) {
      if (index > n) {
        error(std::string(what) + " " + std::to_string(index) + " refers to a vertex that is not defined yet (" +
              std::to_string(n) + " vertices so far)");
      }
      return static_cast<int32_t>(index - 1);
    }
    if (index < 0) {
      if (-index > n) {
        error("relative " + std::string(what) + " " + std::to_string(index) + " reaches before the first vertex (" +
              std::to_string(n) + " vertices so far)");
      }
      return static_cast<int32_t>(n + index);
    }
    error(std::string(what) + " 0 is invalid: OBJ indices start at 1 (or are negative for relative indices)");
  }

  void parse_face(LineCursor& cur) {
    const size_t start = indices_.size();
    while (!cur.at_end()) {
      std::string_view corner = cur.token();
      // Only the first of v/vt/vn is geometry; the others must still be well formed.
      size_t slash = corner.find('/');
      std::string_view v = corner.substr(0, slash);
      if (slash != std::string_view::npos) {
        std::string_view rest = corner.substr(slash + 1);
        size_t slash2 = rest.find('/');
        std::string_view vt = rest.substr(0, slash2);
        std::string_view vn = slash2 == std::string_view::npos ? std::string_view{} : rest.substr(slash2 + 1);
        int64_t ignored = 0;
        if ((!vt.empty() && !parse_int64(vt, ignored)) ||
            (slash2 != std::string_view::npos && !parse_int64(vn, ignored))) {
          error("face corner " + quoted(corner) + " is not of the form v, v/vt, v//vn or v/vt/vn");
        }
      }
      indices_.push_back(resolve_index(v, "face vertex index"));
      if (static_cast<int64_t>(indices_.size()) > options_.max_face_indices) {
        error("more than " + std::to_string(options_.max_face_indices) + " face indices");
      }
      if (static_cast<int64_t>(indices_.size() - start) > options_.max_face_size) {
        error("a face with more than " + std::to_string(options_.max_face_size) + " corners");
      }
    }
    const size_t size = indices_.size() - start;
    if (size < 3) error("a face needs at least 3 vertices, this one has " + std::to_string(size));
    face_sizes_.push_back(static_cast<int32_t>(size));
    if (options_.validate) face_lines_.push_back(current_line_);
  }

  // "t name ni/nf/ns ints... floats... strings..."
  void parse_tag(LineCursor& cur) {
    std::string_view name = cur.token();
    std::string_view counts = cur.token();
    if (name.empty() || counts.empty()) error("a tag needs a name and counts: 't name ni/nf/ns ...'");
    int64_t n[3] = {0, 0, 0};
    {
      std::string_view rest = counts;
      for (int i = 0; i < 3; ++i) {
        size_t slash = rest.find('/');
        std::string_view part = rest.substr(0, slash);
        if (!parse_int64(part, n[i]) || n[i] < 0 || n[i] > 1'000'000) {
          error("tag counts " + quoted(counts) + " must be three non-negative integers 'ni/nf/ns'");
        }
        if (i < 2 && slash == std::string_view::npos) error("tag counts " + quoted(counts) + " must be 'ni/nf/ns'");
        rest = slash == std::string_view::npos ? std::string_view{} : rest.substr(slash + 1);
      }
    }
    std::vector<int64_t> ints(static_cast<size_t>(n[0]));
    std::vector<double> floats(static_cast<size_t>(n[1]));
    for (auto& value : ints) {
      std::string_view tok = cur.token();
      if (!parse_int64(tok, value)) error("tag '" + std::string(name) + "': expected an integer, got " + quoted(tok));
    }
    for (auto& value : floats) {
      std::string_view tok = cur.token();
      if (!parse_double(tok, value)) error("tag '" + std::string(name) + "': expected a number, got " + quoted(tok));
    }
    auto vertex = [&](int64_t i) {
      if (i < 0 || i > std::numeric_limits<int32_t>::max()) {
        error("tag '" + std::string(name) + "': vertex index " + std::to_string(i) + " is out of range");
      }
      return static_cast<int32_t>(i);  // 0-based, as in OpenSubdiv; range-checked by validation
    };
    auto sharpness = [&](double s) {
      if (!std::isfinite(s) || s < 0.0) error("tag '" + std::string(name) + "': sharpness must be >= 0");
      return static_cast<float>(s);
    };
    if (name == "crease") {
      // Either one sharpness for a chain of vertices, or one per edge.
      if (n[0] < 2 || n[1] < 1) error("tag 'crease' needs at least two vertices and one sharpness");
      const int64_t edges = n[0] - 1;
      if (n[1] != 1 && n[1] != edges) error("tag 'crease' needs one sharpness, or one per edge");
      for (int64_t e = 0; e < edges; ++e) {
        mesh_creases_.push_back({vertex(ints[static_cast<size_t>(e)]), vertex(ints[static_cast<size_t>(e + 1)]),
                                 sharpness(floats[static_cast<size_t>(n[1] == 1 ? 0 : e)])});
      }
    } else if (name == "corner") {
      if (n[0] < 1 || (n[1] != 1 && n[1] != n[0])) error("tag 'corner' needs vertices and one sharpness (or one each)");
      for (int64_t i = 0; i < n[0]; ++i) {
        mesh_corners_.push_back({vertex(ints[static_cast<size_t>(i)]), sharpness(floats[static_cast<size_t>(n[1] == 1 ? 0 : i)])});
      }
    } else if (name == "interpolateboundary") {
      if (n[0] != 1) error("tag 'interpolateboundary' needs one integer (0 = none, 1 = edge, 2 = edge and corner)");
      // OpenSubdiv's 1 (edge only) and 2 (edge and corner) both map to the protocol's edge_and_corner.
      boundary_ = ints[0] == 0 ? BoundaryMode::kNone : BoundaryMode::kEdgeAndCorner;
    }
    // Other OpenSubdiv tags (hole, facevaryingpropagatecorners, ...) do not change the vertex
    // limit surface we simulate: skipped.
  }

  ControlMesh finish() {
    ControlMesh mesh(std::move(positions_), face_sizes_, std::move(indices_));
    mesh.creases() = std::move(mesh_creases_);
    mesh.corners() = std::move(mesh_corners_);
    mesh.set_boundary(boundary_);
    if (options_.validate) check(mesh);
    return mesh;
  }

  // --- validation in the file's terms (OBJ numbers vertices from 1; each face has its line) ---
  std::string at_line(int64_t line) const { return std::string(source_) + ":" + std::to_string(line) + ": "; }
  std::string at_face(int32_t f) const { return at_line(face_lines_[static_cast<size_t>(f)]); }
  static std::string vertex(int32_t v) { return "vertex " + std::to_string(int64_t{v} + 1); }
  static std::string corners(const ControlMesh& mesh, int32_t f) {
    std::string out = "(vertices";
    auto face = mesh.face(f);
    for (size_t i = 0; i < face.size() && i < 8; ++i) out += " " + std::to_string(int64_t{face[i]} + 1);
    return out + (face.size() > 8 ? " ...)" : ")");
  }

  // The faces along the edge a-b (each with its direction a -> b), found again for the message.
  static std::vector<std::pair<int32_t, bool>> faces_on_edge(const ControlMesh& mesh, int32_t a, int32_t b) {
    std::vector<std::pair<int32_t, bool>> out;
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      auto face = mesh.face(f);
      for (size_t i = 0; i < face.size(); ++i) {
        const int32_t p = face[i], q = face[(i + 1) % face.size()];
        if ((p == a && q == b) || (p == b && q == a)) out.emplace_back(f, p == a);
      }
    }
    return out;
  }

  // The edge of face f at vertex a that `bad` says is wrong, as (a, b).
  template <class Bad>
  static std::pair<int32_t, int32_t> edge_at(const ControlMesh& mesh, int32_t f, int32_t a, Bad&& bad) {
    auto face = mesh.face(f);
    for (size_t i = 0; i < face.size(); ++i) {
      const int32_t p = face[i], q = face[(i + 1) % face.size()];
      if ((p == a || q == a) && bad(faces_on_edge(mesh, p, q))) return {std::min(p, q), std::max(p, q)};
    }
    return {a, a};
  }

  std::string describe(const ControlMesh& mesh, const MeshIssue& issue) const {
    using K = MeshIssueKind;
    const int32_t f = issue.face, v = issue.vertex;
    switch (issue.kind) {
      case K::kEmpty:
        return std::string(source_) + (mesh.num_vertices() == 0 ? ": the file has no vertices ('v' lines)"
                                                                 : ": the file has no faces ('f' lines)");
      case K::kRepeatedIndex:
        return at_face(f) + "the face uses " + vertex(v) + " twice " + corners(mesh, f);
      case K::kZeroAreaFace:
        return at_face(f) + "the face " + corners(mesh, f) + " has zero area (its vertices are coincident or collinear)";
      case K::kUnusedVertex:
        return at_line(vertex_lines_[static_cast<size_t>(v)]) + vertex(v) + " belongs to no face; remove it";
      case K::kNonManifoldEdge: {
        const auto [a, b] = edge_at(mesh, f, v, [](const auto& on) { return on.size() > 2; });
        std::string lines;
        for (const auto& [g, forward] : faces_on_edge(mesh, a, b)) {
          lines += (lines.empty() ? "" : ", ") + std::to_string(face_lines_[static_cast<size_t>(g)]);
        }
        return at_face(f) + "the edge between vertices " + std::to_string(int64_t{a} + 1) + " and " +
               std::to_string(int64_t{b} + 1) + " belongs to the faces on lines " + lines +
               "; a surface edge may belong to at most 2 faces";
      }
      case K::kNonManifoldVertex:
        return at_face(f) + "this face meets other faces only at " + vertex(v) +
               " (through no edge there): the surface pinches to a point; give each fan of faces its own vertex, "
               "or join the faces through an edge";
      case K::kInconsistentOrientation: {
        const auto same = [](const auto& on) { return on.size() == 2 && on[0].second == on[1].second; };
        const auto [a, b] = edge_at(mesh, f, v, same);
        const auto on = faces_on_edge(mesh, a, b);
        const int32_t other = on.size() == 2 ? (on[0].first == f ? on[1].first : on[0].first) : f;
        return at_face(f) + "this face and the face on line " + std::to_string(face_lines_[static_cast<size_t>(other)]) +
               " run along their shared edge " + std::to_string(int64_t{a} + 1) + "-" + std::to_string(int64_t{b} + 1) +
               " in the same direction: their orientations disagree (reverse the order of one face's vertices)";
      }
      default:  // tags (which count vertices from 0, as OpenSubdiv does) and what the parser rules out
        return std::string(source_) + ": " + issue.message;
    }
  }

  void check(const ControlMesh& mesh) const {
    const std::vector<MeshIssue> issues = find_mesh_issues(mesh, 64);
    if (issues.empty()) return;
    std::string message = describe(mesh, issues.front());
    if (issues.size() > 1) {
      message += " (and " + std::to_string(issues.size() - 1) + (issues.size() >= 64 ? " or more" : "") +
                 " other problem" + (issues.size() > 2 ? "s" : "") + ")";
    }
    fail(issues.front().code(), message);
  }

  std::string_view source_;
  ObjReadOptions options_;
  int64_t line_number_ = 0;
  int64_t current_line_ = 0;
  std::vector<Vec3> positions_;
  std::vector<int32_t> face_sizes_;
  std::vector<int32_t> indices_;
  std::vector<int64_t> vertex_lines_, face_lines_;  // only with options_.validate
  std::vector<Crease> mesh_creases_;
  std::vector<Corner> mesh_corners_;
  BoundaryMode boundary_ = BoundaryMode::kEdgeAndCorner;
};

void append_double(std::string& out, double value) {
  char buf[32];
  auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, value);  // shortest round-trip form
  out.append(buf, ptr);
}

Result<void> write_text(const std::filesystem::path& path, const std::string& text) {
  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  if (!file) return Error{ErrorCode::kIoError, "cannot open '" + path.string() + "' for writing"};
  file.write(text.data(), static_cast<std::streamsize>(text.size()));
  if (!file) return Error{ErrorCode::kIoError, "writing '" + path.string() + "' failed"};
  return {};
}

}  // namespace

Result<ControlMesh> parse_obj(std::string_view text, std::string_view source_name, const ObjReadOptions& options) {
  return capture([&] { return ObjParser(source_name, options).parse(text); });
}

Result<ControlMesh> read_obj(const std::filesystem::path& path, const ObjReadOptions& options) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    return Error{ErrorCode::kIoError, "'" + path.string() + "' is a directory, not an OBJ file"};
  }
  std::ifstream file(path, std::ios::binary);
  if (!file) {
    return Error{ErrorCode::kIoError, "cannot open '" + path.string() + "' for reading: " + std::strerror(errno)};
  }
  std::ostringstream buffer;
  buffer << file.rdbuf();
  if (file.bad()) return Error{ErrorCode::kIoError, "reading '" + path.string() + "' failed"};
  return parse_obj(buffer.str(), path.string(), options);
}

std::string format_obj(const ControlMesh& mesh) {
  std::string out = "# softshell control mesh: " + std::to_string(mesh.num_vertices()) + " vertices, " +
                    std::to_string(mesh.num_faces()) + " faces\n";
  for (const Vec3& p : mesh.positions()) {
    out += "v ";
    append_double(out, p.x());
    out += ' ';
    append_double(out, p.y());
    out += ' ';
    append_double(out, p.z());
    out += '\n';
  }
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    out += 'f';
    for (int32_t v : mesh.face(f)) out += ' ' + std::to_string(v + 1);
    out += '\n';
  }
  for (const Crease& c : mesh.creases()) {
    out += "t crease 2/1/0 " + std::to_string(c.v0) + ' ' + std::to_string(c.v1) + ' ';
    append_double(out, c.sharpness);
    out += '\n';
  }
  for (const Corner& c : mesh.corners()) {
    out += "t corner 1/1/0 " + std::to_string(c.vertex) + ' ';
    append_double(out, c.sharpness);
    out += '\n';
  }
  if (mesh.boundary() == BoundaryMode::kNone) out += "t interpolateboundary 1/0/0 0\n";
  return out;
}

Result<void> write_obj(const ControlMesh& mesh, const std::filesystem::path& path) {
  return write_text(path, format_obj(mesh));
}

std::string format_triangles_obj(const std::vector<Vec3>& vertices,
                                 const std::vector<std::array<int32_t, 3>>& triangles,
                                 const std::vector<Vec3>& normals) {
  const bool with_normals = !normals.empty() && normals.size() == vertices.size();
  std::string out = "# softshell tessellated limit surface: " + std::to_string(vertices.size()) + " vertices, " +
                    std::to_string(triangles.size()) + " triangles\n";
  char buf[128];
  for (const Vec3& p : vertices) {
    int n = std::snprintf(buf, sizeof buf, "v %.9g %.9g %.9g\n", p.x(), p.y(), p.z());
    out.append(buf, static_cast<size_t>(n));
  }
  if (with_normals) {
    for (const Vec3& p : normals) {
      int n = std::snprintf(buf, sizeof buf, "vn %.6g %.6g %.6g\n", p.x(), p.y(), p.z());
      out.append(buf, static_cast<size_t>(n));
    }
  }
  for (const auto& t : triangles) {
    int n = with_normals ? std::snprintf(buf, sizeof buf, "f %d//%d %d//%d %d//%d\n", t[0] + 1, t[0] + 1, t[1] + 1,
                                         t[1] + 1, t[2] + 1, t[2] + 1)
                         : std::snprintf(buf, sizeof buf, "f %d %d %d\n", t[0] + 1, t[1] + 1, t[2] + 1);
    out.append(buf, static_cast<size_t>(n));
  }
  return out;
}

Result<void> write_triangles_obj(const std::filesystem::path& path, const std::vector<Vec3>& vertices,
                                 const std::vector<std::array<int32_t, 3>>& triangles,
                                 const std::vector<Vec3>& normals) {
  return write_text(path, format_triangles_obj(vertices, triangles, normals));
}

}  // namespace softshell
