// The topology side of the exact evaluation (see exact_limit.h): canonical 1-rings, regular
// patches and their phantoms, OpenSubdiv's refinement of a 1-ring.
#include "exact_limit.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include <opensubdiv/far/stencilTableFactory.h>

#include "limit_evaluator_impl.h"
#include "softshell/result.h"

namespace softshell::internal {
namespace {

using Index = Far::Index;

// The face across edge (a, b) from `face`, -1 at a boundary, -2 if the edge is missing or not
// manifold.
Index face_across(const Far::TopologyLevel& level, Index face, Index a, Index b) {
  const Index e = level.FindEdge(a, b);
  if (e < 0) return -2;
  auto faces = level.GetEdgeFaces(e);
  if (faces.size() == 1) return faces[0] == face ? -1 : -2;
  if (faces.size() != 2 || faces[0] == faces[1]) return -2;
  if (faces[0] == face) return faces[1];
  if (faces[1] == face) return faces[0];
  return -2;
}

// The faces around corner `c` of `face`, counter-clockwise: from `face` if the fan is closed,
// from the first face after the boundary otherwise.
bool ordered_fan(const Far::TopologyLevel& level, Index c, Index face, std::vector<Index>& out) {
  out.clear();
  const int limit = level.GetVertexFaces(c).size();
  std::vector<Index> ccw, cw;
  bool closed = false;
  for (Index cur = face;;) {
    auto fv = level.GetFaceVertices(cur);
    const int p = position_in(fv, c);
    const Index next = face_across(level, cur, c, fv[(p + fv.size() - 1) % fv.size()]);
    if (next == -2) return false;
    if (next == -1) break;
    if (next == face) {
      closed = true;
      break;
    }
    ccw.push_back(next);
    cur = next;
    if (static_cast<int>(ccw.size()) > limit) return false;
  }
  if (!closed) {
    for (Index cur = face;;) {
      auto fv = level.GetFaceVertices(cur);
      const int p = position_in(fv, c);
      const Index next = face_across(level, cur, c, fv[(p + 1) % fv.size()]);
      if (next == -2) return false;
      if (next == -1) break;
      cw.push_back(next);
      cur = next;
      if (static_cast<int>(cw.size() + ccw.size()) > limit) return false;
    }
  }
  out.assign(cw.rbegin(), cw.rend());
  out.push_back(face);
  out.insert(out.end(), ccw.begin(), ccw.end());
  return static_cast<int>(out.size()) == limit;
}

}  // namespace

int position_in(Far::ConstIndexArray verts, Index v) {
  for (int i = 0; i < verts.size(); ++i) {
    if (verts[i] == v) return i;
  }
  return -1;
}

LocalRefinement refine_local(const std::vector<int32_t>& signature, int levels) {
  std::vector<int32_t> sizes, indices;
  size_t i = 1;
  int32_t num_vertices = 0;
  for (int32_t f = 0; f < signature[0]; ++f) {
    const int32_t n = signature[i++];
    sizes.push_back(n);
    for (int32_t k = 0; k < n; ++k) {
      indices.push_back(signature[i]);
      num_vertices = std::max(num_vertices, signature[i] + 1);
      ++i;
    }
  }
  LocalRefinement out;
  out.base_size = num_vertices;
  const ControlMesh local(std::vector<Vec3>(static_cast<size_t>(num_vertices), Vec3::Zero()), sizes, indices);
  out.refiner = make_refiner(local);
  if (levels > 0) {
    Far::TopologyRefiner::UniformOptions options(levels);
    options.fullTopologyInLastLevel = true;
    out.refiner->RefineUniform(options);
  }
  out.weights.resize(static_cast<size_t>(levels) + 1);
  out.weights[0] = RowMatrix::Identity(num_vertices, num_vertices);
  if (levels == 0) return out;
  Far::StencilTableFactoryReal<double>::Options so;
  so.interpolationMode = Far::StencilTableFactoryReal<double>::INTERPOLATE_VERTEX;
  so.generateOffsets = true;
  so.generateControlVerts = false;
  so.generateIntermediateLevels = true;
  so.factorizeIntermediateLevels = true;
  std::unique_ptr<const Far::StencilTableReal<double>> table(
      Far::StencilTableFactoryReal<double>::Create(*out.refiner, so));
  Index row = 0;
  for (int l = 1; l <= levels; ++l) {
    const int n = out.refiner->GetLevel(l).GetNumVertices();
    RowMatrix& w = out.weights[static_cast<size_t>(l)];
    w.setZero(n, num_vertices);
    for (int v = 0; v < n; ++v, ++row) {
      auto stencil = table->GetStencil(row);
      const Index* idx = stencil.GetVertexIndices();
      const double* wt = stencil.GetWeights();
      for (int k = 0; k < stencil.GetSize(); ++k) w(v, idx[k]) += wt[k];
    }
  }
  if (row != table->GetNumStencils()) fail(ErrorCode::kInternal, "unexpected OpenSubdiv stencil table layout");
  return out;
}

Index child_face_with(const Far::TopologyLevel& parent, const Far::TopologyLevel& child_level, Index face,
                      Index child) {
  for (Index c : parent.GetFaceChildFaces(face)) {
    if (position_in(child_level.GetFaceVertices(c), child) >= 0) return c;
  }
  return -1;
}

// Gauss-Legendre points and weights on [0, 1] (Newton on the Legendre roots).
void gauss_legendre_01(int n, std::vector<double>& points, std::vector<double>& weights) {
  points.assign(static_cast<size_t>(n), 0.0);
  weights.assign(static_cast<size_t>(n), 0.0);
  for (int i = 0; i < n; ++i) {
    double x = std::cos(std::numbers::pi * (i + 0.75) / (n + 0.5));
    double dp = 1.0;
    for (int iter = 0; iter < 100; ++iter) {
      double p0 = 1.0, p1 = x;
      for (int k = 2; k <= n; ++k) {
        const double p2 = ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k;
        p0 = p1;
        p1 = p2;
      }
      if (n == 1) p0 = 1.0, p1 = x;
      dp = n * (x * p1 - p0) / (x * x - 1.0);
      const double dx = p1 / dp;
      x -= dx;
      if (std::abs(dx) < 1e-16) break;
    }
    points[static_cast<size_t>(n - 1 - i)] = 0.5 * (x + 1.0);
    weights[static_cast<size_t>(n - 1 - i)] = 1.0 / ((1.0 - x * x) * dp * dp);
  }
}


bool extract_neighbourhood(const Far::TopologyLevel& level, Index face, int origin, Neighbourhood& out) {
  out.vertices.clear();
  out.signature.clear();
  std::vector<Index> faces;
  std::vector<int32_t> body;
  auto local = [&](Index v) {
    auto it = std::find(out.vertices.begin(), out.vertices.end(), v);
    if (it != out.vertices.end()) return static_cast<int32_t>(it - out.vertices.begin());
    out.vertices.push_back(v);
    return static_cast<int32_t>(out.vertices.size() - 1);
  };
  auto add_face = [&](Index f, Index start_vertex) {
    faces.push_back(f);
    auto fv = level.GetFaceVertices(f);
    const int p = position_in(fv, start_vertex);
    body.push_back(fv.size());
    for (int k = 0; k < fv.size(); ++k) body.push_back(local(fv[(p + k) % fv.size()]));
  };
  auto fv = level.GetFaceVertices(face);
  const int n = fv.size();
  for (int k = 0; k < n; ++k) local(fv[(origin + k) % n]);
  add_face(face, fv[origin]);
  std::vector<Index> fan;
  for (int k = 0; k < n; ++k) {
    const Index c = fv[(origin + k) % n];
    if (!ordered_fan(level, c, face, fan)) return false;
    for (Index g : fan) {
      if (std::find(faces.begin(), faces.end(), g) == faces.end()) add_face(g, c);
    }
  }
  out.signature.reserve(body.size() + 1);
  out.signature.push_back(static_cast<int32_t>(faces.size()));
  out.signature.insert(out.signature.end(), body.begin(), body.end());
  return true;
}

bool is_regular_vertex(const Far::TopologyLevel& level, Index v) {
  if (level.IsVertexNonManifold(v)) return false;
  auto faces = level.GetVertexFaces(v);
  for (Index f : faces) {
    if (level.GetFaceVertices(f).size() != 4) return false;
  }
  return level.IsVertexBoundary(v) ? (faces.size() == 1 || faces.size() == 2) : faces.size() == 4;
}

bool regular_grid(const Far::TopologyLevel& level, Index face, int origin, PatchGrid& out) {
  auto fv = level.GetFaceVertices(face);
  if (fv.size() != 4) return false;
  std::array<std::array<Index, 4>, 4> g;  // g[i][j], i along the first edge
  for (auto& row : g) row.fill(-1);
  std::array<std::array<Index, 3>, 3> cell;  // mesh face of each unit cell, -1 if none
  for (auto& row : cell) row.fill(-1);
  const Index a0 = fv[origin], a1 = fv[(origin + 1) % 4], a2 = fv[(origin + 2) % 4], a3 = fv[(origin + 3) % 4];
  for (Index a : {a0, a1, a2, a3}) {
    if (!is_regular_vertex(level, a)) return false;
  }
  g[1][1] = a0, g[2][1] = a1, g[2][2] = a2, g[1][2] = a3;
  cell[1][1] = face;
  // Crosses the edge A -> B (counter-clockwise in cell (ci, cj)) into the neighbouring cell, whose
  // face lists B, A, A + d, B + d with d the edge's outward normal.
  auto cross = [&](int ci, int cj, std::array<int, 2> A, std::array<int, 2> B) -> bool {
    const int dx = B[1] - A[1], dy = -(B[0] - A[0]);
    const int ni = ci + dx, nj = cj + dy;
    if (ni < 0 || ni > 2 || nj < 0 || nj > 2) return true;
    const Index va = g[A[0]][A[1]], vb = g[B[0]][B[1]];
    const Index nf = face_across(level, cell[ci][cj], va, vb);
    if (nf == -2) return false;
    if (nf == -1) return true;  // boundary: phantoms later
    if (cell[ni][nj] != -1 && cell[ni][nj] != nf) return false;
    auto nv = level.GetFaceVertices(nf);
    if (nv.size() != 4) return false;
    const int p = position_in(nv, vb);
    if (p < 0 || nv[(p + 1) % 4] != va) return false;
    const Index q = nv[(p + 2) % 4], r = nv[(p + 3) % 4];
    Index& gq = g[A[0] + dx][A[1] + dy];
    Index& gr = g[B[0] + dx][B[1] + dy];
    if ((gq != -1 && gq != q) || (gr != -1 && gr != r)) return false;
    gq = q;
    gr = r;
    cell[ni][nj] = nf;
    return true;
  };
  auto cross_all = [&](int ci, int cj) {
    const std::array<std::array<int, 2>, 4> c = {{{ci, cj}, {ci + 1, cj}, {ci + 1, cj + 1}, {ci, cj + 1}}};
    for (int e = 0; e < 4; ++e) {
      if (!cross(ci, cj, c[static_cast<size_t>(e)], c[static_cast<size_t>((e + 1) % 4)])) return false;
    }
    return true;
  };
  if (!cross_all(1, 1)) return false;
  for (auto [ci, cj] : std::array<std::array<int, 2>, 4>{{{1, 0}, {2, 1}, {1, 2}, {0, 1}}}) {
    if (cell[ci][cj] != -1 && !cross_all(ci, cj)) return false;
  }
  // Every regular corner has all its faces in the grid.
  const std::array<std::array<int, 2>, 4> corner_cells0 = {{{1, 1}, {2, 1}, {2, 2}, {1, 2}}};
  for (int c = 0; c < 4; ++c) {
    const auto [i, j] = corner_cells0[static_cast<size_t>(c)];
    int count = 0;
    for (int di = -1; di <= 0; ++di) {
      for (int dj = -1; dj <= 0; ++dj) count += cell[i + di][j + dj] != -1;
    }
    if (count != level.GetVertexFaces(g[i][j]).size()) return false;
  }
  for (int j = 0; j < 4; ++j) {
    for (int i = 0; i < 4; ++i) out.index[static_cast<size_t>(i + 4 * j)] = g[i][j];
  }
  return true;
}

RowMatrix grid_rows(const PatchGrid& grid, const RowMatrix& w) {
  RowMatrix out(16, w.cols());
  std::array<bool, 16> known{};
  for (int k = 0; k < 16; ++k) {
    const Index v = grid.index[static_cast<size_t>(k)];
    known[static_cast<size_t>(k)] = v >= 0;
    if (v >= 0) out.row(k) = w.row(v);
  }
  auto at = [](int i, int j) { return i + 4 * j; };
  // Across a boundary edge the missing row is 2 P_boundary - P_inner: first along the grid's first
  // axis wherever both sources exist, then along the second (a corner point comes out the same
  // either way).
  auto extrapolate = [&](int target, int boundary, int inner) {
    if (known[static_cast<size_t>(target)] || !known[static_cast<size_t>(boundary)] ||
        !known[static_cast<size_t>(inner)]) {
      return;
    }
    out.row(target) = 2.0 * out.row(boundary) - out.row(inner);
    known[static_cast<size_t>(target)] = true;
  };
  for (int j = 0; j < 4; ++j) {
    extrapolate(at(0, j), at(1, j), at(2, j));
    extrapolate(at(3, j), at(2, j), at(1, j));
  }
  for (int i = 0; i < 4; ++i) {
    extrapolate(at(i, 0), at(i, 1), at(i, 2));
    extrapolate(at(i, 3), at(i, 2), at(i, 1));
  }
  if (std::find(known.begin(), known.end(), false) != known.end()) {
    fail(ErrorCode::kInternal, "a regular patch with a control point that is neither present nor a phantom");
  }
  return out;
}

void bspline_basis(double s, double t, double out[6][16]) {
  auto basis = [](double x, double b[4], double d[4], double dd[4]) {
    const double y = 1.0 - x;
    b[0] = y * y * y / 6.0;
    b[1] = (3.0 * x * x * x - 6.0 * x * x + 4.0) / 6.0;
    b[2] = (-3.0 * x * x * x + 3.0 * x * x + 3.0 * x + 1.0) / 6.0;
    b[3] = x * x * x / 6.0;
    d[0] = -0.5 * y * y;
    d[1] = 1.5 * x * x - 2.0 * x;
    d[2] = -1.5 * x * x + x + 0.5;
    d[3] = 0.5 * x * x;
    dd[0] = y;
    dd[1] = 3.0 * x - 2.0;
    dd[2] = -3.0 * x + 1.0;
    dd[3] = x;
  };
  double bs[4], ds[4], dds[4], bt[4], dt[4], ddt[4];
  basis(s, bs, ds, dds);
  basis(t, bt, dt, ddt);
  for (int j = 0; j < 4; ++j) {
    for (int i = 0; i < 4; ++i) {
      const int k = i + 4 * j;
      out[0][k] = bs[i] * bt[j];
      out[1][k] = ds[i] * bt[j];
      out[2][k] = bs[i] * dt[j];
      out[3][k] = dds[i] * bt[j];
      out[4][k] = ds[i] * dt[j];
      out[5][k] = bs[i] * ddt[j];
    }
  }
}

}  // namespace softshell::internal
