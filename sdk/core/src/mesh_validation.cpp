#include "softshell/mesh_validation.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "softshell/disjoint_sets.h"

namespace softshell {
namespace {

std::string face_name(int32_t f) { return "face " + std::to_string(f); }
std::string vertex_name(int32_t v) { return "control point " + std::to_string(v); }

class IssueList {
 public:
  explicit IssueList(size_t max) : max_(max) {}
  bool full() const { return issues_.size() >= max_; }
  void add(MeshIssueKind kind, int32_t face, int32_t vertex, std::string message) {
    if (!full()) issues_.push_back({kind, face, vertex, std::move(message)});
  }
  std::vector<MeshIssue> take() { return std::move(issues_); }
  bool empty() const { return issues_.empty(); }

 private:
  size_t max_;
  std::vector<MeshIssue> issues_;
};

void find_malformed(const ControlMesh& mesh, IssueList& issues) {
  const int32_t n = mesh.num_vertices();
  if (n == 0) issues.add(MeshIssueKind::kEmpty, -1, -1, "the mesh has no control points");
  if (mesh.num_faces() == 0) issues.add(MeshIssueKind::kEmpty, -1, -1, "the mesh has no faces");

  for (int32_t v = 0; v < n && !issues.full(); ++v) {
    if (!mesh.positions()[static_cast<size_t>(v)].allFinite()) {
      issues.add(MeshIssueKind::kNonFinite, -1, v, vertex_name(v) + " has a coordinate that is NaN or infinite");
    }
  }

  std::vector<int32_t> sorted;
  for (int32_t f = 0; f < mesh.num_faces() && !issues.full(); ++f) {
    auto face = mesh.face(f);
    if (face.size() < 3) {
      issues.add(MeshIssueKind::kFaceTooSmall, f, -1,
                 face_name(f) + " has " + std::to_string(face.size()) + " control points; a face needs at least 3");
      continue;
    }
    bool in_range = true;
    for (int32_t v : face) {
      if (v < 0 || v >= n) {
        issues.add(MeshIssueKind::kIndexOutOfRange, f, v,
                   face_name(f) + " refers to control point " + std::to_string(v) + ", but there are only " +
                       std::to_string(n) + " (indices are 0-based)");
        in_range = false;
        break;
      }
    }
    if (!in_range) continue;
    sorted.assign(face.begin(), face.end());
    std::sort(sorted.begin(), sorted.end());
    if (auto dup = std::adjacent_find(sorted.begin(), sorted.end()); dup != sorted.end()) {
      issues.add(MeshIssueKind::kRepeatedIndex, f, *dup, face_name(f) + " uses " + vertex_name(*dup) + " twice");
    }
  }

  for (const Crease& c : mesh.creases()) {
    if (c.v0 < 0 || c.v0 >= n || c.v1 < 0 || c.v1 >= n) {
      issues.add(MeshIssueKind::kIndexOutOfRange, -1, c.v0 < 0 || c.v0 >= n ? c.v0 : c.v1,
                 "a crease refers to control point " + std::to_string(c.v0 < 0 || c.v0 >= n ? c.v0 : c.v1) +
                     ", but there are only " + std::to_string(n));
    } else if (!std::isfinite(c.sharpness) || c.sharpness < 0.0f) {
      issues.add(MeshIssueKind::kBadTag, -1, c.v0,
                 "the crease between control points " + std::to_string(c.v0) + " and " + std::to_string(c.v1) +
                     " has a sharpness that is negative or not finite");
    }
  }
  for (const Corner& c : mesh.corners()) {
    if (c.vertex < 0 || c.vertex >= n) {
      issues.add(MeshIssueKind::kIndexOutOfRange, -1, c.vertex,
                 "a corner tag refers to control point " + std::to_string(c.vertex) + ", but there are only " +
                     std::to_string(n));
    } else if (!std::isfinite(c.sharpness) || c.sharpness < 0.0f) {
      issues.add(MeshIssueKind::kBadTag, -1, c.vertex,
                 "the corner tag of " + vertex_name(c.vertex) + " has a sharpness that is negative or not finite");
    }
  }
}

struct HalfEdge {
  uint64_t key;   // (min, max) vertex pair
  int32_t face;
  bool forward;   // traversed from min to max
  int32_t corner_lo = -1, corner_hi = -1;  // the face's corners (flat indices) at the min and max vertex
  bool operator<(const HalfEdge& o) const { return key < o.key || (key == o.key && face < o.face); }
};

uint64_t edge_key(int32_t a, int32_t b) {
  auto lo = static_cast<uint64_t>(std::min(a, b)), hi = static_cast<uint64_t>(std::max(a, b));
  return (lo << 32) | hi;
}

void find_unusable(const ControlMesh& mesh, IssueList& issues) {
  // Edges, sorted so that the faces of an edge are adjacent.
  std::vector<HalfEdge> edges;
  edges.reserve(mesh.face_indices().size());
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    auto face = mesh.face(f);
    const int32_t first = mesh.face_offsets()[static_cast<size_t>(f)];
    for (size_t i = 0; i < face.size(); ++i) {
      const size_t next = (i + 1) % face.size();
      int32_t a = face[i], b = face[next];
      const auto ca = first + static_cast<int32_t>(i), cb = first + static_cast<int32_t>(next);
      edges.push_back({edge_key(a, b), f, a < b, a < b ? ca : cb, a < b ? cb : ca});
    }
  }
  std::sort(edges.begin(), edges.end());
  for (size_t i = 0; i < edges.size() && !issues.full();) {
    size_t j = i;
    while (j < edges.size() && edges[j].key == edges[i].key) ++j;
    const auto a = static_cast<int32_t>(edges[i].key >> 32), b = static_cast<int32_t>(edges[i].key & 0xffffffffu);
    if (j - i > 2) {
      std::string faces;
      for (size_t k = i; k < j && k < i + 4; ++k) faces += (k == i ? "" : ", ") + std::to_string(edges[k].face);
      if (j - i > 4) faces += ", ...";
      issues.add(MeshIssueKind::kNonManifoldEdge, edges[i].face, a,
                 "the edge between control points " + std::to_string(a) + " and " + std::to_string(b) + " is shared by " +
                     std::to_string(j - i) + " faces (" + faces + "); a surface edge may belong to at most 2 faces");
    } else if (j - i == 2 && edges[i].forward == edges[i + 1].forward) {
      issues.add(MeshIssueKind::kInconsistentOrientation, edges[i + 1].face, a,
                 "faces " + std::to_string(edges[i].face) + " and " + std::to_string(edges[i + 1].face) +
                     " run along their shared edge " + std::to_string(a) + "-" + std::to_string(b) +
                     " in the same direction: their orientations disagree (reverse the order of one face's vertices)");
    }
    i = j;
  }

  // Around every control point its faces must form one fan, joined through the edges at the
  // point: faces that meet only at a corner (two quads sharing one vertex) make the surface pinch
  // to a point, which has no tangent plane there.
  DisjointSets fans(mesh.face_indices().size());  // over the faces' corners
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j].key == edges[i].key) ++j;
    if (j - i == 2) {
      fans.unite(edges[i].corner_lo, edges[i + 1].corner_lo);
      fans.unite(edges[i].corner_hi, edges[i + 1].corner_hi);
    }
    i = j;
  }
  std::vector<int32_t> fan_of(static_cast<size_t>(mesh.num_vertices()), -1), face_of(fan_of.size(), -1);
  std::vector<char> reported(fan_of.size(), 0);
  for (int32_t f = 0; f < mesh.num_faces() && !issues.full(); ++f) {
    const int32_t first = mesh.face_offsets()[static_cast<size_t>(f)];
    for (int32_t c = first; c < mesh.face_offsets()[static_cast<size_t>(f) + 1]; ++c) {
      const auto v = static_cast<size_t>(mesh.face_indices()[static_cast<size_t>(c)]);
      const int32_t fan = fans.find(c);
      if (fan_of[v] < 0) {
        fan_of[v] = fan;
        face_of[v] = f;
      } else if (fan_of[v] != fan && !reported[v]) {
        reported[v] = 1;
        issues.add(MeshIssueKind::kNonManifoldVertex, f, static_cast<int32_t>(v),
                   vertex_name(static_cast<int32_t>(v)) + " joins faces " + std::to_string(face_of[v]) + " and " +
                       std::to_string(f) + ", which meet only there (through no edge): the surface pinches to a " +
                       "point; give each fan of faces its own control point, or join the faces through an edge");
      }
    }
  }

  // Creases must lie on edges.
  for (const Crease& c : mesh.creases()) {
    HalfEdge probe{edge_key(c.v0, c.v1), -1, false};
    auto it = std::lower_bound(edges.begin(), edges.end(), probe);
    if (it == edges.end() || it->key != probe.key) {
      issues.add(MeshIssueKind::kBadTag, -1, c.v0,
                 "a crease joins control points " + std::to_string(c.v0) + " and " + std::to_string(c.v1) +
                     ", which are not connected by an edge of the mesh");
    }
  }

  // Zero-area faces: |Newell normal| against the mesh's size squared.
  const double diag = mesh.bounding_diagonal();
  const double min_area = 1e-14 * diag * diag;
  for (int32_t f = 0; f < mesh.num_faces() && !issues.full(); ++f) {
    auto face = mesh.face(f);
    Vec3 normal = Vec3::Zero();
    const Vec3& origin = mesh.positions()[static_cast<size_t>(face[0])];
    for (size_t i = 1; i + 1 < face.size(); ++i) {
      normal += (mesh.positions()[static_cast<size_t>(face[i])] - origin)
                    .cross(mesh.positions()[static_cast<size_t>(face[i + 1])] - origin);
    }
    if (0.5 * normal.norm() <= min_area) {
      issues.add(MeshIssueKind::kZeroAreaFace, f, -1,
                 face_name(f) + " has zero area (its control points are coincident or collinear)");
    }
  }

  // Control points used by no face have no stiffness.
  std::vector<char> used(static_cast<size_t>(mesh.num_vertices()), 0);
  for (int32_t v : mesh.face_indices()) used[static_cast<size_t>(v)] = 1;
  for (int32_t v = 0; v < mesh.num_vertices() && !issues.full(); ++v) {
    if (!used[static_cast<size_t>(v)]) {
      issues.add(MeshIssueKind::kUnusedVertex, -1, v, vertex_name(v) + " belongs to no face; remove it");
    }
  }
}

}  // namespace

ErrorCode MeshIssue::code() const {
  switch (kind) {
    case MeshIssueKind::kEmpty:
    case MeshIssueKind::kFaceTooSmall:
    case MeshIssueKind::kIndexOutOfRange:
    case MeshIssueKind::kRepeatedIndex:
    case MeshIssueKind::kNonFinite:
    case MeshIssueKind::kBadTag:
      return ErrorCode::kInvalidArgument;
    case MeshIssueKind::kNonManifoldEdge:
    case MeshIssueKind::kNonManifoldVertex:
    case MeshIssueKind::kInconsistentOrientation:
    case MeshIssueKind::kZeroAreaFace:
    case MeshIssueKind::kUnusedVertex:
      return ErrorCode::kUnprocessable;
  }
  return ErrorCode::kInvalidArgument;
}

std::vector<MeshIssue> find_mesh_issues(const ControlMesh& mesh, size_t max_issues) {
  IssueList issues(std::max<size_t>(max_issues, 1));
  find_malformed(mesh, issues);
  // Topology checks assume indices in range; only run them on a well-formed mesh.
  if (issues.empty()) find_unusable(mesh, issues);
  return issues.take();
}

Result<void> validate_mesh(const ControlMesh& mesh) {
  auto issues = find_mesh_issues(mesh, 64);
  if (issues.empty()) return {};
  std::string message = issues.front().message;
  if (issues.size() > 1) {
    message += " (and " + std::to_string(issues.size() - 1) + (issues.size() >= 64 ? " or more" : "") +
               " other problem" + (issues.size() > 2 ? "s" : "") + ")";
  }
  return Error{issues.front().code(), message};
}

}  // namespace softshell
