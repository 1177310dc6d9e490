#include "softshell/tessellation.h"

#include <algorithm>
#include <cmath>
#include <mutex>
#include <string>

#include <opensubdiv/far/topologyLevel.h>

#include "limit_evaluator_impl.h"

namespace softshell {

namespace Far = internal::Far;
using Param = std::array<double, 2>;

// ------------------------------------------------------------------------------------------------
// QuadtreePath

QuadtreePath QuadtreePath::child(int corner) const {
  if (depth >= 32) fail(ErrorCode::kInvalidArgument, "a quadtree path holds at most 32 levels");
  QuadtreePath p = *this;
  p.bits |= static_cast<uint64_t>(corner & 3) << (2 * depth);
  ++p.depth;
  return p;
}

ParamRect QuadtreePath::range() const {
  ParamRect r;
  for (int i = 0; i < depth; ++i) {
    const double hu = 0.5 * (r.u1 - r.u0), hv = 0.5 * (r.v1 - r.v0);
    const int c = corner(i);
    // 0 = (0,0), 1 = (1,0), 2 = (1,1), 3 = (0,1)
    if (c == 1 || c == 2) r.u0 += hu; else r.u1 -= hu;
    if (c == 2 || c == 3) r.v0 += hv; else r.v1 -= hv;
  }
  return r;
}

QuadtreePath QuadtreePath::from_corners(const std::vector<int>& corners) {
  QuadtreePath p;
  for (int c : corners) {
    if (c < 0 || c > 3) fail(ErrorCode::kInvalidArgument, "a quadtree path corner must be 0, 1, 2 or 3");
    p = p.child(c);
  }
  return p;
}

// ------------------------------------------------------------------------------------------------
// Lazily built data

struct Tessellation::Lazy {
  std::mutex mutex;
  std::optional<double> chordal_error;
  std::unique_ptr<Eigen::SparseMatrix<double, Eigen::RowMajor>> position, du, dv;
};

Tessellation::Tessellation() : lazy_(std::make_unique<Lazy>()) {}
Tessellation::Tessellation(Tessellation&&) noexcept = default;
Tessellation& Tessellation::operator=(Tessellation&&) noexcept = default;
Tessellation::~Tessellation() = default;

namespace {

// Corner parameters of a refined face: the (u, v) of each of its vertices in the root (sub-)face.
struct RefinedFace {
  int32_t root_face;
  int32_t subface;
  QuadtreePath path;
  std::array<Param, 4> corner;
};

Param midpoint(const Param& a, const Param& b) { return {0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])}; }

// Which corner (0..3, protocol order) of the rectangle spanned by `corners` the point `p` is.
int rect_corner(const std::array<Param, 4>& corners, const Param& p) {
  double u0 = corners[0][0], u1 = u0, v0 = corners[0][1], v1 = v0;
  for (const Param& c : corners) {
    u0 = std::min(u0, c[0]);
    u1 = std::max(u1, c[0]);
    v0 = std::min(v0, c[1]);
    v1 = std::max(v1, c[1]);
  }
  const bool hi_u = p[0] > 0.5 * (u0 + u1), hi_v = p[1] > 0.5 * (v0 + v1);
  return hi_v ? (hi_u ? 2 : 3) : (hi_u ? 1 : 0);
}

// Corner parameters of the children of `parent` at the next level. The child face's vertices are
// identified through OpenSubdiv's parent -> child vertex relations (vertex, edge and face
// children), so no assumption about the order of child vertices is needed.
void refine_level(const Far::TopologyLevel& parent_level, const Far::TopologyLevel& child_level,
                  const std::vector<RefinedFace>& parents, std::vector<RefinedFace>& children, bool first_level) {
  children.assign(static_cast<size_t>(child_level.GetNumFaces()), RefinedFace{});
  for (Far::Index pf = 0; pf < parent_level.GetNumFaces(); ++pf) {
    const RefinedFace& parent = parents[static_cast<size_t>(pf)];
    auto parent_verts = parent_level.GetFaceVertices(pf);
    auto parent_edges = parent_level.GetFaceEdges(pf);
    auto child_faces = parent_level.GetFaceChildFaces(pf);
    const int n = parent_verts.size();
    const bool splits_into_subfaces = first_level && n != 4;
    const Far::Index center_vertex = parent_level.GetFaceChildVertex(pf);
    for (int k = 0; k < child_faces.size(); ++k) {
      const Far::Index cf = child_faces[k];
      RefinedFace& child = children[static_cast<size_t>(cf)];
      child.root_face = parent.root_face;
      auto child_verts = child_level.GetFaceVertices(cf);
      // For an n-gon's first refinement, the child is the sub-face at the parent corner it
      // contains; it gets its own unit square.
      int subface = -1;
      if (splits_into_subfaces) {
        for (int c = 0; c < 4 && subface < 0; ++c) {
          for (int i = 0; i < n; ++i) {
            if (parent_level.GetVertexChildVertex(parent_verts[i]) == child_verts[c]) subface = i;
          }
        }
        if (subface < 0) fail(ErrorCode::kInternal, "tessellation: an n-gon child face has no corner vertex");
      }
      // Parameters of the points the child's vertices came from.
      std::array<Param, 4> corner_params;
      for (int c = 0; c < 4; ++c) {
        const Far::Index cv = child_verts[c];
        Param p{0.0, 0.0};
        bool found = false;
        if (cv == center_vertex) {
          p = splits_into_subfaces ? Param{1.0, 1.0}
                                   : midpoint(midpoint(parent.corner[0], parent.corner[2]),
                                              midpoint(parent.corner[1], parent.corner[3]));
          found = true;
        }
        for (int i = 0; i < n && !found; ++i) {
          if (parent_level.GetVertexChildVertex(parent_verts[i]) == cv) {
            p = splits_into_subfaces ? Param{0.0, 0.0} : parent.corner[static_cast<size_t>(i)];
            found = true;
          } else if (parent_level.GetEdgeChildVertex(parent_edges[i]) == cv) {
            // Edge i runs from corner i to corner i+1. In sub-face k, edge k's midpoint is (1,0)
            // and edge k-1's midpoint is (0,1).
            if (splits_into_subfaces) {
              p = (i == subface) ? Param{1.0, 0.0} : Param{0.0, 1.0};
            } else {
              p = midpoint(parent.corner[static_cast<size_t>(i)], parent.corner[static_cast<size_t>((i + 1) % 4)]);
            }
            found = true;
          }
        }
        if (!found) {
          fail(ErrorCode::kInternal,
               "tessellation: a refined vertex of face " + std::to_string(parent.root_face) + " has no parent component");
        }
        corner_params[static_cast<size_t>(c)] = p;
      }
      child.corner = corner_params;
      if (splits_into_subfaces) {
        child.subface = subface;
        child.path = QuadtreePath{};
      } else {
        child.subface = parent.subface;
        // The quadrant of the parent's rectangle that the child's centre lies in.
        Param centre = midpoint(midpoint(corner_params[0], corner_params[2]), midpoint(corner_params[1], corner_params[3]));
        child.path = parent.path.child(rect_corner(parent.corner, centre));
      }
    }
  }
}

}  // namespace

Result<Tessellation> Tessellation::create(const LimitEvaluator& evaluator, int level, int64_t max_triangles) {
  return capture([&]() -> Tessellation {
    if (level < 0 || level > 8) {
      fail(ErrorCode::kInvalidArgument, "tessellation level must be between 0 and 8, got " + std::to_string(level));
    }
    const LimitEvaluator::Impl& ev = *evaluator.impl_;
    const ControlMesh& mesh = ev.mesh;
    // Refined quad count: n-gons become n quads at level 1, every quad 4 at each level.
    int64_t quads = 0;
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      if (!evaluator.has_limit_surface(f)) continue;
      const int64_t n = mesh.face_size(f);
      quads += level == 0 ? (n == 4 ? 1 : 0) : (n == 4 ? 4 : n) * (int64_t{1} << (2 * (level - 1)));
    }
    if (2 * quads > max_triangles) {
      fail(ErrorCode::kResourceExhausted, "tessellation level " + std::to_string(level) + " would have " +
                                              std::to_string(2 * quads) + " triangles (limit " +
                                              std::to_string(max_triangles) + "); use a lower level");
    }
    if (level == 0 && !mesh.all_quads()) {
      fail(ErrorCode::kInvalidArgument, "level 0 can only be tessellated when every face is a quad; use level >= 1");
    }

    Tessellation t;
    t.evaluator_ = evaluator;
    t.level_ = level;
    t.control_positions_ = mesh.positions();

    // Uniform refinement of the topology (the evaluator's refiner stays at the base level).
    std::unique_ptr<Far::TopologyRefiner> refiner = internal::make_refiner(mesh);
    if (level > 0) {
      Far::TopologyRefiner::UniformOptions options(level);
      options.fullTopologyInLastLevel = true;
      refiner->RefineUniform(options);
    }

    // Corner parameters, level by level.
    std::vector<RefinedFace> current(static_cast<size_t>(mesh.num_faces()));
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      current[static_cast<size_t>(f)] = RefinedFace{f, 0, {}, {Param{0, 0}, Param{1, 0}, Param{1, 1}, Param{0, 1}}};
    }
    std::vector<RefinedFace> next;
    for (int l = 1; l <= level; ++l) {
      refine_level(refiner->GetLevel(l - 1), refiner->GetLevel(l), current, next, l == 1);
      current.swap(next);
    }

    // Quads of faces that have a limit surface, and one surface point per refined vertex.
    const Far::TopologyLevel& last = refiner->GetLevel(level);
    const auto num_vertices = static_cast<size_t>(last.GetNumVertices());
    std::vector<int32_t> vertex_map(num_vertices, -1);  // refiner vertex -> our vertex
    for (Far::Index f = 0; f < last.GetNumFaces(); ++f) {
      const RefinedFace& rf = current[static_cast<size_t>(f)];
      if (!evaluator.has_limit_surface(rf.root_face)) continue;
      auto verts = last.GetFaceVertices(f);
      Quad q;
      q.root_face = rf.root_face;
      q.subface = rf.subface;
      q.path = rf.path;
      q.rotation = static_cast<uint8_t>(rect_corner(rf.corner, rf.corner[0]));
      for (int c = 0; c < 4; ++c) {
        int32_t& mapped = vertex_map[static_cast<size_t>(verts[c])];
        if (mapped < 0) {
          mapped = static_cast<int32_t>(t.vertex_points_.size());
          const Param& p = rf.corner[static_cast<size_t>(c)];
          t.vertex_points_.push_back(SurfacePoint{rf.root_face, rf.subface, p[0], p[1]});
        }
        q.vertices[static_cast<size_t>(c)] = mapped;
      }
      t.quads_.push_back(q);
    }
    t.triangles_.reserve(2 * t.quads_.size());
    for (const Quad& q : t.quads_) {
      t.triangles_.push_back({q.vertices[0], q.vertices[1], q.vertices[2]});
      t.triangles_.push_back({q.vertices[0], q.vertices[2], q.vertices[3]});
    }

    // Limit positions and normals, grouped by (face, sub-face) so each Bfr surface is prepared once.
    const size_t nv = t.vertex_points_.size();
    t.vertices_.resize(nv);
    t.normals_.resize(nv);
    std::vector<int32_t> order(nv);
    for (size_t i = 0; i < nv; ++i) order[i] = static_cast<int32_t>(i);
    std::sort(order.begin(), order.end(), [&](int32_t a, int32_t b) {
      const SurfacePoint &pa = t.vertex_points_[static_cast<size_t>(a)], &pb = t.vertex_points_[static_cast<size_t>(b)];
      return pa.face != pb.face ? pa.face < pb.face : (pa.subface != pb.subface ? pa.subface < pb.subface : a < b);
    });
    std::vector<Param> uvs;
    std::vector<Vec3> pos, du, dv;
    std::vector<double> scratch;
    for (size_t i = 0; i < nv;) {
      const SurfacePoint& first = t.vertex_points_[static_cast<size_t>(order[i])];
      size_t j = i;
      uvs.clear();
      while (j < nv && t.vertex_points_[static_cast<size_t>(order[j])].face == first.face &&
             t.vertex_points_[static_cast<size_t>(order[j])].subface == first.subface) {
        const SurfacePoint& p = t.vertex_points_[static_cast<size_t>(order[j])];
        uvs.push_back({p.u, p.v});
        ++j;
      }
      pos.resize(uvs.size());
      du.resize(uvs.size());
      dv.resize(uvs.size());
      ev.evaluate_many(first.face, first.subface, uvs.data(), uvs.size(), mesh.positions(), pos.data(), du.data(),
                       dv.data(), scratch);
      for (size_t k = 0; k < uvs.size(); ++k) {
        const auto v = static_cast<size_t>(order[i + k]);
        t.vertices_[v] = pos[k];
        Vec3 n = du[k].cross(dv[k]);
        t.normals_[v] = n.norm() > 0.0 ? Vec3(n.normalized()) : Vec3::Zero();
      }
      i = j;
    }
    return t;
  });
}

std::array<std::array<double, 2>, 4> Tessellation::quad_corner_params(int32_t quad) const {
  if (quad < 0 || static_cast<size_t>(quad) >= quads_.size()) {
    fail(ErrorCode::kInvalidArgument, "quad index " + std::to_string(quad) + " is out of range");
  }
  const Quad& q = quads_[static_cast<size_t>(quad)];
  const ParamRect r = q.path.range();
  const std::array<Param, 4> rect = {Param{r.u0, r.v0}, Param{r.u1, r.v0}, Param{r.u1, r.v1}, Param{r.u0, r.v1}};
  std::array<Param, 4> out;
  for (size_t i = 0; i < 4; ++i) out[i] = rect[(i + q.rotation) % 4];
  return out;
}

SurfacePoint Tessellation::surface_point(int32_t triangle, const std::array<double, 3>& barycentric) const {
  if (triangle < 0 || static_cast<size_t>(triangle) >= triangles_.size()) {
    fail(ErrorCode::kInvalidArgument, "triangle index " + std::to_string(triangle) + " is out of range (" +
                                          std::to_string(triangles_.size()) + " triangles)");
  }
  const int32_t quad = triangle / 2;
  const auto corners = quad_corner_params(quad);
  // Triangle 2q is quad corners (0, 1, 2), triangle 2q + 1 is (0, 2, 3).
  const std::array<size_t, 3> tri = (triangle % 2 == 0) ? std::array<size_t, 3>{0, 1, 2} : std::array<size_t, 3>{0, 2, 3};
  double u = 0.0, v = 0.0;
  for (size_t i = 0; i < 3; ++i) {
    u += barycentric[i] * corners[tri[i]][0];
    v += barycentric[i] * corners[tri[i]][1];
  }
  const Quad& q = quads_[static_cast<size_t>(quad)];
  return SurfacePoint{q.root_face, q.subface, std::clamp(u, 0.0, 1.0), std::clamp(v, 0.0, 1.0)};
}

double Tessellation::chordal_error() const {
  std::lock_guard lock(lazy_->mutex);
  if (lazy_->chordal_error) return *lazy_->chordal_error;
  const LimitEvaluator::Impl& ev = *evaluator_->impl_;
  // A barycentric grid with 6 steps per edge: 28 points per triangle.
  constexpr int kSteps = 6;
  std::vector<std::array<double, 3>> bary;
  for (int i = 0; i <= kSteps; ++i) {
    for (int j = 0; i + j <= kSteps; ++j) {
      bary.push_back({double(kSteps - i - j) / kSteps, double(i) / kSteps, double(j) / kSteps});
    }
  }
  double max_error = 0.0;
  std::vector<Param> uvs(bary.size());
  std::vector<Vec3> limit(bary.size());
  std::vector<double> scratch;
  for (size_t t = 0; t < triangles_.size(); ++t) {
    const auto& tri = triangles_[t];
    int32_t face = 0, subface = 0;
    for (size_t s = 0; s < bary.size(); ++s) {
      SurfacePoint p = surface_point(static_cast<int32_t>(t), bary[s]);
      face = p.face;
      subface = p.subface;
      uvs[s] = {p.u, p.v};
    }
    ev.evaluate_many(face, subface, uvs.data(), uvs.size(), ev.mesh.positions(), limit.data(), nullptr, nullptr,
                     scratch);
    // Rest-shape triangle corners (vertices_ may have been moved by update()).
    Vec3 corner[3];
    for (size_t c = 0; c < 3; ++c) {
      const SurfacePoint& vp = vertex_points_[static_cast<size_t>(tri[c])];
      Param uv{vp.u, vp.v};
      ev.evaluate_many(vp.face, vp.subface, &uv, 1, ev.mesh.positions(), &corner[c], nullptr, nullptr, scratch);
    }
    for (size_t s = 0; s < bary.size(); ++s) {
      const Vec3 on_triangle = bary[s][0] * corner[0] + bary[s][1] * corner[1] + bary[s][2] * corner[2];
      max_error = std::max(max_error, (on_triangle - limit[s]).norm());
    }
  }
  lazy_->chordal_error = max_error;
  return max_error;
}

const Eigen::SparseMatrix<double, Eigen::RowMajor>& Tessellation::limit_matrix() const {
  std::lock_guard lock(lazy_->mutex);
  if (!lazy_->position) {
    using Sparse = Eigen::SparseMatrix<double, Eigen::RowMajor>;
    std::vector<Eigen::Triplet<double>> tp, tu, tv;
    LimitStencil st;
    for (size_t i = 0; i < vertex_points_.size(); ++i) {
      evaluator_->stencil(vertex_points_[i], st);
      for (size_t k = 0; k < st.size(); ++k) {
        const auto row = static_cast<int>(i);
        tp.emplace_back(row, st.indices[k], st.position[k]);
        tu.emplace_back(row, st.indices[k], st.du[k]);
        tv.emplace_back(row, st.indices[k], st.dv[k]);
      }
    }
    const auto rows = static_cast<Eigen::Index>(vertex_points_.size());
    const auto cols = static_cast<Eigen::Index>(evaluator_->num_control_points());
    auto build = [&](const std::vector<Eigen::Triplet<double>>& triplets) {
      auto m = std::make_unique<Sparse>(rows, cols);
      m->setFromTriplets(triplets.begin(), triplets.end());
      return m;
    };
    lazy_->position = build(tp);
    lazy_->du = build(tu);
    lazy_->dv = build(tv);
  }
  return *lazy_->position;
}

void Tessellation::update(const std::vector<Vec3>& positions) {
  if (positions.size() != static_cast<size_t>(evaluator_->num_control_points())) {
    fail(ErrorCode::kInvalidArgument, "Tessellation::update expects " +
                                          std::to_string(evaluator_->num_control_points()) +
                                          " control positions, got " + std::to_string(positions.size()));
  }
  const auto& S = limit_matrix();
  const Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>> P(
      positions.front().data(), static_cast<Eigen::Index>(positions.size()), 3);
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> X = S * P;
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> U = *lazy_->du * P;
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> V = *lazy_->dv * P;
  for (Eigen::Index i = 0; i < X.rows(); ++i) {
    vertices_[static_cast<size_t>(i)] = X.row(i).transpose();
    Vec3 n = Vec3(U.row(i).transpose()).cross(Vec3(V.row(i).transpose()));
    normals_[static_cast<size_t>(i)] = n.norm() > 0.0 ? Vec3(n.normalized()) : Vec3::Zero();
  }
  control_positions_ = positions;
}

}  // namespace softshell
