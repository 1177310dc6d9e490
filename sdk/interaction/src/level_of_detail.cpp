// Levels of detail: how each fine face sits in its coarse face (the parameter maps), carrying points,
// constraints and forces between levels, and the parallel coarse/fine simulation. (Long: the maps
// and the transfers are one piece of bookkeeping; ParallelLevels at the end only uses them.)
#include "softshell/level_of_detail.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <thread>

#include <Eigen/SparseCholesky>
#include <opensubdiv/far/stencilTable.h>
#include <opensubdiv/far/stencilTableFactory.h>
#include <opensubdiv/far/topologyLevel.h>

#include "limit_evaluator_impl.h"
#include "softshell/mesh_validation.h"

namespace softshell {

namespace Far = internal::Far;
using Param = std::array<double, 2>;
using SparseRow = Eigen::SparseMatrix<double, Eigen::RowMajor>;
using SparseCol = Eigen::SparseMatrix<double, Eigen::ColMajor>;

namespace {

bool finite(const Vec3& v) { return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z()); }

// A face of refinement level l (>= 1): its parent at level l-1 and where its four corners lie in
// the parent's domain (the parent's sub-face `subface` for the first split of an n-gon).
struct ChildFace {
  int32_t parent = 0;
  int32_t subface = 0;
  std::array<Param, 4> corner{};
};

// (u, v) = c0 + s (c1 - c0) + t (c3 - c0): the affine map from a child's own coordinates (s, t) to
// its parent's. The corners of a child span an axis-aligned square, so it is exactly invertible.
Param child_to_parent(const ChildFace& c, double s, double t) {
  return {c.corner[0][0] + s * (c.corner[1][0] - c.corner[0][0]) + t * (c.corner[3][0] - c.corner[0][0]),
          c.corner[0][1] + s * (c.corner[1][1] - c.corner[0][1]) + t * (c.corner[3][1] - c.corner[0][1])};
}

Param parent_to_child(const ChildFace& c, double u, double v) {
  const double e1u = c.corner[1][0] - c.corner[0][0], e1v = c.corner[1][1] - c.corner[0][1];
  const double e3u = c.corner[3][0] - c.corner[0][0], e3v = c.corner[3][1] - c.corner[0][1];
  const double det = e1u * e3v - e1v * e3u;
  const double du = u - c.corner[0][0], dv = v - c.corner[0][1];
  return {std::clamp((du * e3v - dv * e3u) / det, 0.0, 1.0), std::clamp((e1u * dv - e1v * du) / det, 0.0, 1.0)};
}

bool contains(const ChildFace& c, double u, double v) {
  double u0 = c.corner[0][0], u1 = u0, v0 = c.corner[0][1], v1 = v0;
  for (const Param& p : c.corner) {
    u0 = std::min(u0, p[0]);
    u1 = std::max(u1, p[0]);
    v0 = std::min(v0, p[1]);
    v1 = std::max(v1, p[1]);
  }
  return u >= u0 && u <= u1 && v >= v0 && v <= v1;
}

}  // namespace

struct MeshRefinement::Impl {
  int levels = 0;
  ControlMesh coarse;
  ControlMesh fine;
  SparseRow S;
  SparseCol S_col;                    // the same, column access for kSubdivide
  std::vector<double> column_sums;    // D
  std::vector<std::vector<ChildFace>> children;          // [l - 1][face of level l]
  std::vector<std::vector<int32_t>> child_offsets;       // [l - 1][face of level l-1] -> into child_list
  std::vector<std::vector<int32_t>> child_list;          // [l - 1]
  std::vector<int32_t> coarse_subfaces;                  // per coarse face: 1 for quads, n for n-gons
  mutable std::once_flag normal_once;
  mutable std::unique_ptr<Eigen::SimplicialLDLT<SparseCol>> normal_factor;  // SᵀS
  mutable std::string normal_error;

  // Maps a coarse point down the levels; also returns d(u, v)_coarse / d(s, t)_fine (columns).
  SurfacePoint to_fine(const SurfacePoint& p, Param& out_ds, Param& out_dt) const {
    int32_t face = p.face;
    double u = p.u, v = p.v;
    out_ds = {1.0, 0.0};
    out_dt = {0.0, 1.0};
    for (int l = 1; l <= levels; ++l) {
      const auto& offsets = child_offsets[static_cast<size_t>(l - 1)];
      const auto& list = child_list[static_cast<size_t>(l - 1)];
      const auto& info = children[static_cast<size_t>(l - 1)];
      const bool split = l == 1 && coarse_subfaces[static_cast<size_t>(face)] != 1;
      int32_t found = -1;
      for (int32_t k = offsets[static_cast<size_t>(face)]; k < offsets[static_cast<size_t>(face) + 1] && found < 0; ++k) {
        const ChildFace& c = info[static_cast<size_t>(list[static_cast<size_t>(k)])];
        if (split ? c.subface == p.subface : contains(c, u, v)) found = list[static_cast<size_t>(k)];
      }
      if (found < 0) fail(ErrorCode::kInternal, "level of detail: no child face contains the point");
      const ChildFace& c = info[static_cast<size_t>(found)];
      const Param st = parent_to_child(c, u, v);
      // Chain rule: d(parent)/d(child) is (c1 - c0, c3 - c0); accumulate coarse <- fine.
      const Param e1{c.corner[1][0] - c.corner[0][0], c.corner[1][1] - c.corner[0][1]};
      const Param e3{c.corner[3][0] - c.corner[0][0], c.corner[3][1] - c.corner[0][1]};
      const Param ds{out_ds[0] * e1[0] + out_dt[0] * e1[1], out_ds[1] * e1[0] + out_dt[1] * e1[1]};
      const Param dt{out_ds[0] * e3[0] + out_dt[0] * e3[1], out_ds[1] * e3[0] + out_dt[1] * e3[1]};
      out_ds = ds;
      out_dt = dt;
      face = found;
      u = st[0];
      v = st[1];
    }
    return SurfacePoint{face, 0, u, v};
  }

  const Eigen::SimplicialLDLT<SparseCol>& normal_matrix() const {
    std::call_once(normal_once, [&] {
      SparseCol StS = SparseCol(S.transpose()) * S_col;
      auto factor = std::make_unique<Eigen::SimplicialLDLT<SparseCol>>(StS);
      if (factor->info() != Eigen::Success) {
        normal_error = "the refinement matrix S has dependent columns";
        return;
      }
      normal_factor = std::move(factor);
    });
    if (!normal_factor) fail(ErrorCode::kInternal, normal_error);
    return *normal_factor;
  }

  void check_coarse_vertex(int32_t i, const char* what) const {
    if (i < 0 || i >= coarse.num_vertices()) {
      fail(ErrorCode::kInvalidArgument, std::string(what) + " index " + std::to_string(i) + " is out of range (" +
                                            std::to_string(coarse.num_vertices()) + " control points)");
    }
  }
};

MeshRefinement::MeshRefinement() : impl_(std::make_unique<Impl>()) {}
MeshRefinement::MeshRefinement(MeshRefinement&&) noexcept = default;
MeshRefinement& MeshRefinement::operator=(MeshRefinement&&) noexcept = default;
MeshRefinement::~MeshRefinement() = default;

int MeshRefinement::levels() const { return impl_->levels; }
const ControlMesh& MeshRefinement::coarse() const { return impl_->coarse; }
const ControlMesh& MeshRefinement::fine() const { return impl_->fine; }
const SparseRow& MeshRefinement::matrix() const { return impl_->S; }

Result<MeshRefinement> MeshRefinement::create(const ControlMesh& tagged_coarse, int levels, int64_t max_fine_vertices,
                                              bool sharp_features) {
  return capture([&]() -> MeshRefinement {
    if (levels < 1 || levels > 6) {
      fail(ErrorCode::kInvalidArgument, "refinement levels must be between 1 and 6, got " + std::to_string(levels));
    }
    validate_mesh(tagged_coarse).value();
    // Size estimate: each level multiplies the vertex count by about 4.
    const int64_t estimate = static_cast<int64_t>(tagged_coarse.face_indices().size()) << (2 * levels);
    if (estimate > 4 * max_fine_vertices) {
      fail(ErrorCode::kResourceExhausted, "refining " + std::to_string(levels) + " levels would give about " +
                                              std::to_string(estimate / 4) + " control points (limit " +
                                              std::to_string(max_fine_vertices) + ")");
    }

    // The surface being refined: without its tags unless they are to shape it (as in the evaluator).
    ControlMesh coarse = tagged_coarse;
    if (!sharp_features) {
      coarse.creases().clear();
      coarse.corners().clear();
    }
    MeshRefinement out;
    Impl& m = *out.impl_;
    m.levels = levels;
    m.coarse = coarse;
    std::unique_ptr<Far::TopologyRefiner> refiner = internal::make_refiner(coarse);
    Far::TopologyRefiner::UniformOptions uniform(levels);
    uniform.orderVerticesFromFacesFirst = false;  // children of vertices first: coarse i -> fine i
    uniform.fullTopologyInLastLevel = true;       // edges and sharpness of the fine mesh
    refiner->RefineUniform(uniform);
    const Far::TopologyLevel& last = refiner->GetLevel(levels);
    if (last.GetNumVertices() > max_fine_vertices) {
      fail(ErrorCode::kResourceExhausted, "the refined mesh would have " + std::to_string(last.GetNumVertices()) +
                                              " control points (limit " + std::to_string(max_fine_vertices) + ")");
    }

    // Coarse control point i is fine control point i, level by level.
    for (int l = 0; l < levels; ++l) {
      const Far::TopologyLevel& parent = refiner->GetLevel(l);
      for (Far::Index v = 0; v < parent.GetNumVertices(); ++v) {
        if (parent.GetVertexChildVertex(v) != v) {
          fail(ErrorCode::kInternal, "OpenSubdiv did not number the child of vertex " + std::to_string(v) +
                                         " at level " + std::to_string(l + 1) + " as " + std::to_string(v));
        }
      }
    }

    // S from OpenSubdiv's stencils of the last level, in double precision.
    Far::StencilTableFactoryReal<double>::Options so;
    so.interpolationMode = Far::StencilTableFactoryReal<double>::INTERPOLATE_VERTEX;
    so.generateOffsets = true;
    so.generateControlVerts = false;
    so.generateIntermediateLevels = false;
    so.factorizeIntermediateLevels = true;
    std::unique_ptr<const Far::StencilTableReal<double>> table(Far::StencilTableFactoryReal<double>::Create(*refiner, so));
    if (!table || table->GetNumStencils() != last.GetNumVertices()) {
      fail(ErrorCode::kInternal, "OpenSubdiv did not produce one stencil per refined vertex");
    }
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(table->GetControlIndices().size());
    for (int i = 0; i < table->GetNumStencils(); ++i) {
      const auto st = table->GetStencil(i);
      for (int k = 0; k < st.GetSize(); ++k) triplets.emplace_back(i, st.GetVertexIndices()[k], st.GetWeights()[k]);
    }
    m.S.resize(last.GetNumVertices(), coarse.num_vertices());
    m.S.setFromTriplets(triplets.begin(), triplets.end());
    m.S.makeCompressed();
    m.S_col = m.S;
    m.column_sums.assign(static_cast<size_t>(coarse.num_vertices()), 0.0);
    for (Eigen::Index r = 0; r < m.S.outerSize(); ++r) {
      for (SparseRow::InnerIterator it(m.S, r); it; ++it) m.column_sums[static_cast<size_t>(it.col())] += it.value();
    }

    // The fine control mesh: positions S x_c, faces, carried creases and corners.
    std::vector<Vec3> positions(static_cast<size_t>(last.GetNumVertices()));
    {
      const Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>> X(
          coarse.positions().front().data(), coarse.num_vertices(), 3);
      Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> Y = m.S * X;
      for (Eigen::Index i = 0; i < Y.rows(); ++i) positions[static_cast<size_t>(i)] = Y.row(i).transpose();
    }
    std::vector<int32_t> sizes(static_cast<size_t>(last.GetNumFaces()));
    std::vector<int32_t> indices;
    indices.reserve(static_cast<size_t>(last.GetNumFaceVertices()));
    for (Far::Index f = 0; f < last.GetNumFaces(); ++f) {
      const auto fv = last.GetFaceVertices(f);
      sizes[static_cast<size_t>(f)] = fv.size();
      for (int k = 0; k < fv.size(); ++k) indices.push_back(fv[k]);
    }
    m.fine = ControlMesh(std::move(positions), sizes, std::move(indices));
    m.fine.set_boundary(coarse.boundary());
    if (coarse.has_sharpness()) {
      // Sharpness decreases by one a level; boundary edges are sharp by the boundary rules anyway.
      for (Far::Index e = 0; e < last.GetNumEdges(); ++e) {
        const float s = last.GetEdgeSharpness(e);
        if (s > 0.0f && !last.IsEdgeBoundary(e)) {
          const auto ev = last.GetEdgeVertices(e);
          m.fine.creases().push_back(Crease{ev[0], ev[1], s});
        }
      }
      for (Far::Index v = 0; v < last.GetNumVertices(); ++v) {
        const float s = last.GetVertexSharpness(v);
        if (s > 0.0f) m.fine.corners().push_back(Corner{v, s});
      }
    }

    // Where every refined face sits in its parent, level by level.
    m.coarse_subfaces.resize(static_cast<size_t>(coarse.num_faces()));
    for (int32_t f = 0; f < coarse.num_faces(); ++f) {
      m.coarse_subfaces[static_cast<size_t>(f)] = coarse.face_size(f) == 4 ? 1 : coarse.face_size(f);
    }
    static constexpr std::array<Param, 4> kQuadCorners = {Param{0, 0}, Param{1, 0}, Param{1, 1}, Param{0, 1}};
    auto mid = [](const Param& a, const Param& b) { return Param{0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])}; };
    for (int l = 1; l <= levels; ++l) {
      const Far::TopologyLevel& P = refiner->GetLevel(l - 1);
      const Far::TopologyLevel& C = refiner->GetLevel(l);
      auto& info = m.children.emplace_back(static_cast<size_t>(C.GetNumFaces()));
      auto& offsets = m.child_offsets.emplace_back(static_cast<size_t>(P.GetNumFaces()) + 1, 0);
      auto& list = m.child_list.emplace_back();
      for (Far::Index pf = 0; pf < P.GetNumFaces(); ++pf) {
        const auto pv = P.GetFaceVertices(pf);
        const auto pe = P.GetFaceEdges(pf);
        const int n = pv.size();
        const bool split = l == 1 && n != 4;
        const Far::Index centre = P.GetFaceChildVertex(pf);
        const auto kids = P.GetFaceChildFaces(pf);
        for (int k = 0; k < kids.size(); ++k) {
          const Far::Index cf = kids[k];
          list.push_back(cf);
          ChildFace& c = info[static_cast<size_t>(cf)];
          c.parent = pf;
          const auto cv = C.GetFaceVertices(cf);
          if (cv.size() != 4) fail(ErrorCode::kInternal, "a refined face is not a quad");
          int sub = 0;
          if (split) {
            sub = -1;
            for (int i = 0; i < n && sub < 0; ++i) {
              for (int j = 0; j < 4; ++j) {
                if (P.GetVertexChildVertex(pv[i]) == cv[j]) sub = i;
              }
            }
            if (sub < 0) fail(ErrorCode::kInternal, "an n-gon's child face has no corner vertex");
          }
          c.subface = sub;
          for (int j = 0; j < 4; ++j) {
            bool found = false;
            if (cv[j] == centre) {
              c.corner[static_cast<size_t>(j)] = split ? Param{1, 1} : Param{0.5, 0.5};
              found = true;
            }
            for (int i = 0; i < n && !found; ++i) {
              if (P.GetVertexChildVertex(pv[i]) == cv[j]) {
                c.corner[static_cast<size_t>(j)] = split ? Param{0, 0} : kQuadCorners[static_cast<size_t>(i)];
                found = true;
              } else if (P.GetEdgeChildVertex(pe[i]) == cv[j]) {
                // Edge i runs from corner i to corner i + 1; in sub-face k edge k's midpoint is
                // (1, 0) and edge k-1's is (0, 1).
                c.corner[static_cast<size_t>(j)] =
                    split ? (i == sub ? Param{1, 0} : Param{0, 1})
                          : mid(kQuadCorners[static_cast<size_t>(i)], kQuadCorners[static_cast<size_t>((i + 1) % 4)]);
                found = true;
              }
            }
            if (!found) fail(ErrorCode::kInternal, "a refined vertex has no parent component");
          }
        }
        offsets[static_cast<size_t>(pf) + 1] = static_cast<int32_t>(list.size());
      }
    }
    return out;
  });
}

Result<std::vector<Vec3>> MeshRefinement::refine_positions(const std::vector<Vec3>& coarse_positions) const {
  return capture([&]() -> std::vector<Vec3> {
    if (coarse_positions.size() != static_cast<size_t>(impl_->coarse.num_vertices())) {
      fail(ErrorCode::kInvalidArgument, "expected " + std::to_string(impl_->coarse.num_vertices()) +
                                            " coarse positions, got " + std::to_string(coarse_positions.size()));
    }
    const Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>> X(
        coarse_positions.front().data(), static_cast<Eigen::Index>(coarse_positions.size()), 3);
    Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> Y = impl_->S * X;
    std::vector<Vec3> out(static_cast<size_t>(Y.rows()));
    for (Eigen::Index i = 0; i < Y.rows(); ++i) out[static_cast<size_t>(i)] = Y.row(i).transpose();
    return out;
  });
}

LimitEvaluator::Options MeshRefinement::fine_evaluator_options(const LimitEvaluator::Options& coarse_options) const {
  LimitEvaluator::Options o = coarse_options;
  o.approx_level_smooth = std::max(1, coarse_options.approx_level_smooth - impl_->levels);
  o.approx_level_sharp = std::max(1, coarse_options.approx_level_sharp - impl_->levels);
  return o;
}

Result<SurfacePoint> MeshRefinement::fine_point(const SurfacePoint& p) const {
  return capture([&]() -> SurfacePoint {
    const ControlMesh& c = impl_->coarse;
    if (p.face < 0 || p.face >= c.num_faces()) {
      fail(ErrorCode::kInvalidArgument, "face index " + std::to_string(p.face) + " is out of range (" +
                                            std::to_string(c.num_faces()) + " faces)");
    }
    if (p.subface < 0 || p.subface >= impl_->coarse_subfaces[static_cast<size_t>(p.face)]) {
      fail(ErrorCode::kInvalidArgument, "face " + std::to_string(p.face) + " has no sub-face " + std::to_string(p.subface));
    }
    if (!(p.u >= 0.0 && p.u <= 1.0 && p.v >= 0.0 && p.v <= 1.0)) {
      fail(ErrorCode::kInvalidArgument, "(u, v) must lie in [0, 1] x [0, 1]");
    }
    Param ds, dt;
    return impl_->to_fine(p, ds, dt);
  });
}

Result<SurfacePoint> MeshRefinement::coarse_point(const SurfacePoint& p) const {
  return capture([&]() -> SurfacePoint {
    const ControlMesh& f = impl_->fine;
    if (p.face < 0 || p.face >= f.num_faces() || p.subface != 0 || !(p.u >= 0.0 && p.u <= 1.0) ||
        !(p.v >= 0.0 && p.v <= 1.0)) {
      fail(ErrorCode::kInvalidArgument, "not a point of the fine mesh: face " + std::to_string(p.face) + " sub-face " +
                                            std::to_string(p.subface) + " (u, v) = (" + std::to_string(p.u) + ", " +
                                            std::to_string(p.v) + ")");
    }
    int32_t face = p.face, subface = 0;
    double u = p.u, v = p.v;
    for (int l = impl_->levels; l >= 1; --l) {
      const ChildFace& c = impl_->children[static_cast<size_t>(l - 1)][static_cast<size_t>(face)];
      const Param uv = child_to_parent(c, u, v);
      u = std::clamp(uv[0], 0.0, 1.0);
      v = std::clamp(uv[1], 0.0, 1.0);
      subface = l == 1 ? c.subface : 0;
      face = c.parent;
    }
    return SurfacePoint{face, subface, u, v};
  });
}

Result<std::vector<VertexConstraint>> MeshRefinement::vertex_constraints_to_fine(
    const std::vector<VertexConstraint>& coarse) const {
  return capture([&]() -> std::vector<VertexConstraint> {
    for (const VertexConstraint& c : coarse) {
      impl_->check_coarse_vertex(c.index, "vertex constraint");
      if (c.mask == 0 || c.mask > 7) fail(ErrorCode::kInvalidArgument, "vertex constraint mask must be 1..7");
      if (!finite(c.displacement)) fail(ErrorCode::kInvalidArgument, "vertex constraint displacement is not finite");
    }
    return coarse;  // coarse point i is fine point i (checked when built)
  });
}

Result<LimitConstraint> MeshRefinement::limit_constraint_to_fine(const LimitConstraint& coarse) const {
  return capture([&]() -> LimitConstraint {
    SurfacePoint p = fine_point(coarse.point).value();
    if (!finite(coarse.displacement) || (coarse.du_displacement && !finite(*coarse.du_displacement)) ||
        (coarse.dv_displacement && !finite(*coarse.dv_displacement))) {
      fail(ErrorCode::kInvalidArgument, "limit constraint displacement is not finite");
    }
    Param ds, dt;
    p = impl_->to_fine(coarse.point, ds, dt);
    LimitConstraint out;
    out.point = p;
    out.displacement = coarse.displacement;
    // Tangents are derivatives w.r.t. the face's own (u, v): x_s = u_s x_u + v_s x_v on the fine face.
    auto tangent = [&](const Param& d) -> std::optional<Vec3> {
      Vec3 sum = Vec3::Zero();
      if (d[0] != 0.0) {
        if (!coarse.du_displacement) return std::nullopt;
        sum += d[0] * *coarse.du_displacement;
      }
      if (d[1] != 0.0) {
        if (!coarse.dv_displacement) return std::nullopt;
        sum += d[1] * *coarse.dv_displacement;
      }
      return sum;
    };
    out.du_displacement = tangent(ds);
    out.dv_displacement = tangent(dt);
    return out;
  });
}

Result<std::vector<PointForce>> MeshRefinement::forces_to_fine(const std::vector<PointForce>& coarse,
                                                               ForceTransfer transfer) const {
  return capture([&]() -> std::vector<PointForce> {
    const auto nc = static_cast<size_t>(impl_->coarse.num_vertices());
    const auto nf = static_cast<size_t>(impl_->fine.num_vertices());
    Eigen::Matrix<double, Eigen::Dynamic, 3> fc = Eigen::Matrix<double, Eigen::Dynamic, 3>::Zero(static_cast<Eigen::Index>(nc), 3);
    for (const PointForce& f : coarse) {
      impl_->check_coarse_vertex(f.index, "force");
      if (!finite(f.force)) fail(ErrorCode::kInvalidArgument, "force on control point " + std::to_string(f.index) + " is not finite");
      fc.row(f.index) += f.force.transpose();
    }
    std::vector<PointForce> out;
    if (coarse.empty()) return out;
    if (transfer == ForceTransfer::kSubdivide) {
      std::vector<Vec3> ff(nf, Vec3::Zero());
      std::vector<char> touched(nf, 0);
      for (size_t j = 0; j < nc; ++j) {
        if (fc.row(static_cast<Eigen::Index>(j)).isZero(0.0)) continue;
        const Vec3 scaled = fc.row(static_cast<Eigen::Index>(j)).transpose() / impl_->column_sums[j];
        for (SparseCol::InnerIterator it(impl_->S_col, static_cast<Eigen::Index>(j)); it; ++it) {
          ff[static_cast<size_t>(it.row())] += it.value() * scaled;
          touched[static_cast<size_t>(it.row())] = 1;
        }
      }
      for (size_t i = 0; i < nf; ++i) {
        if (touched[i]) out.push_back(PointForce{static_cast<int32_t>(i), ff[i]});
      }
      return out;
    }
    const Eigen::Matrix<double, Eigen::Dynamic, 3> y = impl_->normal_matrix().solve(fc);
    const Eigen::Matrix<double, Eigen::Dynamic, 3> ff = impl_->S * y;
    out.reserve(nf);
    for (size_t i = 0; i < nf; ++i) {
      const Vec3 f = ff.row(static_cast<Eigen::Index>(i)).transpose();
      if (!f.isZero(0.0)) out.push_back(PointForce{static_cast<int32_t>(i), f});
    }
    return out;
  });
}

Result<std::vector<PointForce>> MeshRefinement::forces_to_coarse(const std::vector<PointForce>& fine) const {
  return capture([&]() -> std::vector<PointForce> {
    const auto nc = static_cast<size_t>(impl_->coarse.num_vertices());
    std::vector<Vec3> fc(nc, Vec3::Zero());
    std::vector<char> touched(nc, 0);
    for (const PointForce& f : fine) {
      if (f.index < 0 || f.index >= impl_->fine.num_vertices()) {
        fail(ErrorCode::kInvalidArgument, "fine force index " + std::to_string(f.index) + " is out of range (" +
                                              std::to_string(impl_->fine.num_vertices()) + " control points)");
      }
      if (!finite(f.force)) fail(ErrorCode::kInvalidArgument, "force on control point " + std::to_string(f.index) + " is not finite");
      for (SparseRow::InnerIterator it(impl_->S, f.index); it; ++it) {
        fc[static_cast<size_t>(it.col())] += it.value() * f.force;
        touched[static_cast<size_t>(it.col())] = 1;
      }
    }
    std::vector<PointForce> out;
    for (size_t j = 0; j < nc; ++j) {
      if (touched[j]) out.push_back(PointForce{static_cast<int32_t>(j), fc[j]});
    }
    return out;
  });
}

Result<DeformationRequest> MeshRefinement::request_to_fine(const DeformationRequest& coarse,
                                                           ForceTransfer transfer) const {
  return capture([&]() -> DeformationRequest {
    DeformationRequest fine;
    fine.vertex_constraints = vertex_constraints_to_fine(coarse.vertex_constraints).value();
    for (const LagrangeConstraint& c : coarse.lagrange_constraints) {
      if (c.indices.size() != c.coefficients.size()) {
        fail(ErrorCode::kInvalidArgument, "a Lagrange constraint needs one coefficient triple per index");
      }
      for (int32_t i : c.indices) impl_->check_coarse_vertex(i, "Lagrange constraint");
      fine.lagrange_constraints.push_back(c);  // by the control point correspondence
    }
    fine.forces = forces_to_fine(coarse.forces, transfer).value();
    for (const LimitConstraint& c : coarse.limit_constraints) {
      fine.limit_constraints.push_back(limit_constraint_to_fine(c).value());
    }
    for (const SurfaceForce& f : coarse.surface_forces) {
      if (!finite(f.force)) fail(ErrorCode::kInvalidArgument, "surface force is not finite");
      fine.surface_forces.push_back(SurfaceForce{fine_point(f.point).value(), f.force});
    }
    if (!finite(coarse.surface_load) || !std::isfinite(coarse.pressure)) {
      fail(ErrorCode::kInvalidArgument, "surface load and pressure must be finite");
    }
    fine.surface_load = coarse.surface_load;
    fine.pressure = coarse.pressure;
    return fine;
  });
}

// ------------------------------------------------------------------------------------------------
// ParallelLevels

ParallelLevels::ParallelLevels(Session& session, MeshRefinement refinement, GeomId coarse, GeomId fine,
                               ForceTransfer transfer)
    : session_(session), refinement_(std::move(refinement)), coarse_id_(coarse), fine_id_(fine), transfer_(transfer) {}

ParallelLevels::~ParallelLevels() {
  std::lock_guard lock(mutex_);
  for (Pending& p : pending_) p.future.wait();
}

Result<std::unique_ptr<ParallelLevels>> ParallelLevels::create(Session& session, const ControlMesh& coarse,
                                                               const Material& material, int levels,
                                                               std::string_view name_space, ForceTransfer transfer) {
  return capture([&]() -> std::unique_ptr<ParallelLevels> {
    MeshRefinement refinement = MeshRefinement::create(coarse, levels).value();
    const UploadResult c = session.upload(refinement.coarse(), material, name_space).value();
    const UploadResult f = session.upload(refinement.fine(), material, name_space).value();
    return std::unique_ptr<ParallelLevels>(new ParallelLevels(session, std::move(refinement), c.id, f.id, transfer));
  });
}

Result<uint64_t> ParallelLevels::submit(const DeformationRequest& coarse_request) {
  return capture([&]() -> uint64_t {
    // Validate and transfer before sending anything.
    const DeformationRequest fine_request = refinement_.request_to_fine(coarse_request, transfer_).value();
    std::lock_guard lock(mutex_);
    const uint64_t id = next_submission_++;
    pending_.push_back(Pending{id, false, session_.deform_async(coarse_id_, coarse_request).share()});
    pending_.push_back(Pending{id, true, session_.deform_async(fine_id_, fine_request).share()});
    return id;
  });
}

std::optional<LevelResult> ParallelLevels::take_ready() {
  auto key = [](const Pending& p) { return 2 * p.submission + (p.fine ? 1 : 0); };
  // The newest ready result that is newer than what was delivered.
  int best = -1;
  for (size_t i = 0; i < pending_.size(); ++i) {
    if (key(pending_[i]) <= delivered_key_) continue;
    if (pending_[i].future.wait_for(std::chrono::seconds(0)) != std::future_status::ready) continue;
    if (best < 0 || key(pending_[i]) > key(pending_[static_cast<size_t>(best)])) best = static_cast<int>(i);
  }
  std::optional<LevelResult> out;
  if (best >= 0) {
    const Pending& p = pending_[static_cast<size_t>(best)];
    out = LevelResult{p.submission, p.fine, p.future.get()};
    delivered_key_ = key(p);
  }
  // Drop what can no longer be delivered once it is finished (a pending future is kept until then,
  // so that no request is abandoned mid-flight).
  std::erase_if(pending_, [&](const Pending& p) {
    return key(p) <= delivered_key_ && p.future.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
  });
  return out;
}

std::optional<LevelResult> ParallelLevels::poll() {
  std::lock_guard lock(mutex_);
  return take_ready();
}

std::optional<LevelResult> ParallelLevels::wait(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (true) {
    std::shared_future<Result<DeformationResult>> next;
    {
      std::lock_guard lock(mutex_);
      if (auto r = take_ready()) return r;
      // Wait on the oldest request that can still be delivered.
      for (const Pending& p : pending_) {
        if (2 * p.submission + (p.fine ? 1 : 0) > delivered_key_) {
          next = p.future;
          break;
        }
      }
    }
    if (!next.valid()) return std::nullopt;
    const auto now = std::chrono::steady_clock::now();
    if (now >= deadline) return std::nullopt;
    // Short slices: another request may finish first.
    next.wait_for(std::min<std::chrono::steady_clock::duration>(deadline - now, std::chrono::milliseconds(2)));
  }
}

size_t ParallelLevels::in_flight() const {
  std::lock_guard lock(mutex_);
  size_t n = 0;
  for (const Pending& p : pending_) n += 2 * p.submission + (p.fine ? 1 : 0) > delivered_key_ ? 1 : 0;
  return n;
}

}  // namespace softshell
