#include "exact_limit.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <numbers>

#include <Eigen/LU>
#include <Eigen/QR>
#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/stencilTableFactory.h>
#include <opensubdiv/far/topologyRefiner.h>

#include "limit_evaluator_impl.h"
#include "softshell/result.h"

namespace softshell::internal {
namespace {

using Index = Far::Index;

int position_in(Far::ConstIndexArray verts, Index v) {
  for (int i = 0; i < verts.size(); ++i) {
    if (verts[i] == v) return i;
  }
  return -1;
}

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

// A Far refiner of the topology in a signature, refined uniformly, with every refined vertex as
// weights over the base vertices.
struct LocalRefinement {
  std::unique_ptr<Far::TopologyRefiner> refiner;
  std::vector<RowMatrix> weights;  // per level: vertices x base vertices
  int base_size = 0;
};

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

// The child face of `face` (next level) that contains child vertex `child`, or -1.
Index child_face_with(const Far::TopologyLevel& parent, const Far::TopologyLevel& child_level, Index face,
                      Index child) {
  for (Index c : parent.GetFaceChildFaces(face)) {
    if (position_in(child_level.GetFaceVertices(c), child) >= 0) return c;
  }
  return -1;
}

// Dense points of a primvar refiner's "vertex" buffer: rows of a matrix.
struct MaskRow {
  double* w = nullptr;
  Eigen::Index n = 0;
  void Clear() { std::fill(w, w + n, 0.0); }
  void AddWithWeight(const MaskRow& src, double weight) {
    for (Eigen::Index i = 0; i < n; ++i) w[i] += weight * src.w[i];
  }
};

std::vector<MaskRow> rows_of(RowMatrix& m) {
  std::vector<MaskRow> rows(static_cast<size_t>(m.rows()));
  for (Eigen::Index i = 0; i < m.rows(); ++i) rows[static_cast<size_t>(i)] = {m.row(i).data(), m.cols()};
  return rows;
}

// Orthonormal basis of the invariant subspace of the two eigenvalues of largest modulus of m
// (orthogonal iteration; for Catmull-Clark's deflated subdivision matrices they are well
// separated from the rest, and the callers check the result).
Eigen::MatrixXd dominant_pair(const Eigen::MatrixXd& m) {
  Eigen::MatrixXd q(m.rows(), 2);
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    q(i, 0) = std::sin(1.0 + static_cast<double>(i));
    q(i, 1) = std::cos(2.0 + 3.0 * static_cast<double>(i));
  }
  const Eigen::MatrixXd first_two = Eigen::MatrixXd::Identity(m.rows(), 2);
  for (int it = 0; it < 1000; ++it) {
    const Eigen::HouseholderQR<Eigen::MatrixXd> qr(m * q);
    q = qr.householderQ() * first_two;
  }
  return q;
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

}  // namespace

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

// ---------------------------------------------------------------------------------------------
// EvConfig

std::unique_ptr<EvConfig> EvConfig::build(const std::vector<int32_t>& signature) {
  // Local vertex 0 is the extraordinary corner, local face 0 the quad, its corners 0, 1, 2, 3.
  if (signature.size() < 6 || signature[1] != 4) return nullptr;
  LocalRefinement local = refine_local(signature, 1);
  const int k = local.base_size;
  const Far::TopologyLevel& l0 = local.refiner->GetLevel(0);
  const Far::TopologyLevel& l1 = local.refiner->GetLevel(1);
  for (Index f = 0; f < l0.GetNumFaces(); ++f) {
    if (position_in(l0.GetFaceVertices(f), 0) >= 0 && l0.GetFaceVertices(f).size() != 4) return nullptr;
  }
  const RowMatrix& w1 = local.weights[1];

  // The child at the corner has the same numbered 1-ring: A.
  const Index corner_child = l0.GetVertexChildVertex(0);
  const Index child = child_face_with(l0, l1, 0, corner_child);
  if (child < 0) return nullptr;
  Neighbourhood hood;
  if (!extract_neighbourhood(l1, child, position_in(l1.GetFaceVertices(child), corner_child), hood) ||
      hood.signature != signature) {
    return nullptr;
  }
  auto out = std::unique_ptr<EvConfig>(new EvConfig);
  out->size_ = k;
  out->subdivision_.resize(k, k);
  for (int i = 0; i < k; ++i) out->subdivision_.row(i) = w1.row(hood.vertices[static_cast<size_t>(i)]);
  const RowMatrix& a = out->subdivision_;

  // The other three children are regular patches: their 16 points, the grid's first axis along s.
  const std::array<Index, 3> origins = {l0.GetEdgeChildVertex(l0.FindEdge(0, 1)), l0.GetFaceChildVertex(0),
                                        l0.GetEdgeChildVertex(l0.FindEdge(3, 0))};
  const std::array<Index, 3> along_s = {l0.GetVertexChildVertex(1), l0.GetEdgeChildVertex(l0.FindEdge(1, 2)),
                                        l0.GetFaceChildVertex(0)};
  std::array<RowMatrix, 3> pick;
  for (int c = 1; c <= 3; ++c) {
    const Index f = child_face_with(l0, l1, 0, l0.GetVertexChildVertex(c));
    if (f < 0) return nullptr;
    auto fv = l1.GetFaceVertices(f);
    const int p = position_in(fv, origins[static_cast<size_t>(c - 1)]);
    if (p < 0 || fv[(p + 1) % 4] != along_s[static_cast<size_t>(c - 1)]) return nullptr;
    PatchGrid grid;
    if (!regular_grid(l1, f, p, grid)) return nullptr;
    pick[static_cast<size_t>(c - 1)] = grid_rows(grid, w1);
  }

  // The limit mask l (l A = l, l 1 = 1): a row of A^(2^8), refined by one more application.
  RowMatrix power = a;
  for (int i = 0; i < 8; ++i) power = (power * power).eval();
  out->limit_ = power.row(0) * a;
  out->limit_ /= out->limit_.sum();
  if ((out->limit_ * a - out->limit_).cwiseAbs().maxCoeff() > 1e-12) {
    fail(ErrorCode::kInternal, "the subdivision matrix around an extraordinary vertex has no limit mask");
  }

  // B = A - 1 l has A's eigenvalues but 0 for 1; P_k A^(n-1) = 1 l + P_k B^(n-1) (P_k 1 = 1).
  const RowMatrix ones_l = Eigen::VectorXd::Ones(k) * out->limit_;
  const RowMatrix b = a - ones_l;
  RowMatrix m = RowMatrix::Identity(k, k) - ones_l;  // B^0 on everything but constants
  out->table_.resize(kTableLevels);
  for (int n = 1; n <= kTableLevels; ++n) {
    for (int c = 0; c < 3; ++c) out->table_[static_cast<size_t>(n - 1)][static_cast<size_t>(c)] = pick[static_cast<size_t>(c)] * m;
    m = (m * b).eval();
  }
  out->powers_.push_back(b);
  for (int j = 1; j <= 10; ++j) out->powers_.push_back(out->powers_.back() * out->powers_.back());

  // Tangents at the corner: OpenSubdiv's limit tangent masks. Inside, rotated onto the quad's two
  // edges (edge i of the vertex lies at angle 2 pi i / valence in their frame); on a boundary the
  // two subdominant left eigenvectors of A (OpenSubdiv's boundary masks follow Biermann's rules,
  // not the plain boundary rules it subdivides with).
  out->tangents_.setZero(2, k);
  if (!l0.IsVertexBoundary(0)) {
    LocalRefinement base = refine_local(signature, 0);
    RowMatrix identity = RowMatrix::Identity(k, k), position(k, k), tan1(k, k), tan2(k, k);
    std::vector<MaskRow> src = rows_of(identity), p = rows_of(position), t1 = rows_of(tan1), t2 = rows_of(tan2);
    Far::PrimvarRefinerReal<double>(*base.refiner).Limit(src, p, t1, t2);
    auto edges = l0.GetVertexEdges(0);
    const double theta = 2.0 * std::numbers::pi / edges.size();
    const int ia = position_in(edges, l0.FindEdge(0, 1)), ib = position_in(edges, l0.FindEdge(0, 3));
    out->tangents_.row(0) = std::cos(ia * theta) * tan1.row(0) + std::sin(ia * theta) * tan2.row(0);
    out->tangents_.row(1) = std::cos(ib * theta) * tan1.row(0) + std::sin(ib * theta) * tan2.row(0);
  }
  const Eigen::MatrixXd bd = b;
  if (l0.IsVertexBoundary(0)) {
    const Eigen::MatrixXd y = dominant_pair(bd.transpose());
    out->tangents_.row(0) = y.col(0).transpose();
    out->tangents_.row(1) = y.col(1).transpose();
  }
  // Orientation: in the characteristic map (the subdominant right eigenvectors as a planar
  // embedding) the tangents must turn the same way as the quad's (s, t).
  const Eigen::MatrixXd chart = dominant_pair(bd);
  out->chart_ = chart;
  out->chart_ratio_ = (chart.transpose() * Eigen::MatrixXd(a) * chart).determinant();
  if (!(std::abs(out->chart_ratio_) < 1.0) || (Eigen::MatrixXd(a) * chart - chart * (chart.transpose() * Eigen::MatrixXd(a) * chart)).norm() > 1e-9) {
    fail(ErrorCode::kInternal, "the dominant eigenvalues of the subdivision matrix at an extraordinary vertex are not separated");
  }
  std::vector<double> w(6 * static_cast<size_t>(k));
  out->evaluate(0.75, 0.75, w.data());
  const Eigen::Map<const RowMatrix> wm(w.data(), 6, k);
  const Eigen::Matrix2d st = (wm.middleRows(1, 2) * chart).eval();
  const Eigen::Matrix2d at_corner = out->tangents_ * chart;
  if (st.determinant() * at_corner.determinant() < 0.0) out->tangents_.row(1) *= -1.0;
  if (!(std::abs(at_corner.determinant()) > 0.0)) {
    fail(ErrorCode::kInternal, "no tangent plane at an extraordinary vertex");
  }
  return out;
}

EvConfig::Location EvConfig::locate(double s, double t) {
  Location at;
  const double m = std::max(s, t);
  int e = 0;
  (void)std::frexp(m, &e);  // m in [2^(e-1), 2^e)
  if (!(m > 0.0) || e < -998) return at;  // the corner itself
  at.ring = std::max(1, 1 - e);  // the ring [2^-n, 2^-(n-1)] of sub-patches at level n
  const double scale = std::ldexp(1.0, at.ring);
  const double ss = std::min(2.0, s * scale), tt = std::min(2.0, t * scale);
  if (ss >= 1.0) {  // sub-patch 1 (along s), 2 (diagonal), 3 (along t)
    at.patch = tt >= 1.0 ? 2 : 1;
    at.a = ss - 1.0;
    at.b = tt >= 1.0 ? tt - 1.0 : tt;
  } else {
    at.patch = 3;
    at.a = ss;
    at.b = tt - 1.0;
  }
  at.a = std::clamp(at.a, 0.0, 1.0);
  at.b = std::clamp(at.b, 0.0, 1.0);
  return at;
}

const RowMatrix& EvConfig::ring_points(int ring, int patch, RowMatrix& deep) const {
  if (ring <= kTableLevels) return table_[static_cast<size_t>(ring - 1)][static_cast<size_t>(patch - 1)];
  deep = table_[kTableLevels - 1][static_cast<size_t>(patch - 1)];
  for (int bits = ring - kTableLevels, j = 0; bits; bits >>= 1, ++j) {
    if (bits & 1) deep = (deep * powers_[static_cast<size_t>(j)]).eval();
  }
  return deep;
}

void EvConfig::basis_rows(const Location& at, double* out) {
  double basis[6][16];
  bspline_basis(at.a, at.b, basis);
  const double scale = std::ldexp(1.0, at.ring);
  const double order_scale[6] = {1.0, scale, scale, scale * scale, scale * scale, scale * scale};
  for (int r = 0; r < 6; ++r) {
    for (int i = 0; i < 16; ++i) out[16 * r + i] = basis[r][i] * order_scale[r];
  }
}

void EvConfig::evaluate(double s, double t, double* out) const {
  const int k = size_;
  Eigen::Map<Eigen::Matrix<double, 6, Eigen::Dynamic, Eigen::RowMajor>> result(out, 6, k);
  const Location at = locate(s, t);
  if (at.ring == 0) {
    result.setZero();
    result.row(0) = limit_;
    result.middleRows(1, 2) = tangents_;
    return;
  }
  Eigen::Matrix<double, 6, 16, Eigen::RowMajor> rows;
  basis_rows(at, rows.data());
  RowMatrix deep;
  result.noalias() = rows * ring_points(at.ring, at.patch, deep);
  result.row(0) += limit_;
}

const std::vector<double>& EvConfig::corner_rule(int g) const {
  std::lock_guard lock(rules_mutex_);
  auto it = rules_.find(g);
  if (it == rules_.end()) it = rules_.emplace(g, compute_corner_rule(g)).first;
  return it->second;
}

std::vector<double> EvConfig::compute_corner_rule(int g) const {
  const auto points = static_cast<size_t>(g) * static_cast<size_t>(g);
  std::vector<double> out(points, 1.0);
  if (g < 2) return out;
  const int k = size_;
  std::vector<double> w(6 * static_cast<size_t>(k));
  // The Jacobian of the characteristic map at (s, t).
  auto jacobian = [&](double s, double t) {
    evaluate(s, t, w.data());
    const Eigen::Map<const RowMatrix> wm(w.data(), 6, k);
    const Eigen::RowVector2d ps = wm.row(1) * chart_, pt = wm.row(2) * chart_;
    return ps[0] * pt[1] - ps[1] * pt[0];
  };
  // Exactly: ring 1 (three polynomial squares) times 1 / (1 - det M), the rings inside being
  // scaled copies of it.
  std::vector<double> rx, rw;
  gauss_legendre_01(5, rx, rw);
  double ring = 0.0;
  for (const auto& sq : std::array<std::array<double, 2>, 3>{{{0.5, 0.0}, {0.5, 0.5}, {0.0, 0.5}}}) {
    for (size_t i = 0; i < rx.size(); ++i) {
      for (size_t j = 0; j < rx.size(); ++j) ring += 0.25 * rw[i] * rw[j] * jacobian(sq[0] + 0.5 * rx[i], sq[1] + 0.5 * rx[j]);
    }
  }
  const double exact = ring / (1.0 - chart_ratio_);
  // The g x g rule, corrected by factors 1 + c J(point) (the smallest change, in the
  // Gauss-weighted norm, that makes it exact for J).
  std::vector<double> gx, gw;
  gauss_legendre_01(g, gx, gw);
  std::vector<double> jac(points), w0(points);
  double gauss = 0.0, norm = 0.0;
  for (int j = 0; j < g; ++j) {
    for (int i = 0; i < g; ++i) {
      const auto p = static_cast<size_t>(i + g * j);
      jac[p] = jacobian(gx[static_cast<size_t>(i)], gx[static_cast<size_t>(j)]);
      w0[p] = gw[static_cast<size_t>(i)] * gw[static_cast<size_t>(j)];
      gauss += w0[p] * jac[p];
      norm += w0[p] * jac[p] * jac[p];
    }
  }
  if (!(norm > 0.0)) return out;
  const double c = (exact - gauss) / norm;
  for (size_t p = 0; p < points; ++p) out[p] = 1.0 + c * jac[p];
  if (*std::min_element(out.begin(), out.end()) < 0.5) std::fill(out.begin(), out.end(), 1.0);  // never: the
  return out;                                                                                      // error is ~1e-4
}

const std::vector<double>& EvConfig::normal_tensor() const {
  std::call_once(normal_once_, [this] {
    const int k = size_;
    const auto kk = static_cast<size_t>(k);
    // Ring 1: U1[a][b][c] = integral of phi_a phi_b,s phi_c,t (degree 8 in s and t: 5 points).
    std::vector<double> u(kk * kk * kk, 0.0), w(6 * kk);
    std::vector<double> rx, rw;
    gauss_legendre_01(5, rx, rw);
    for (const auto& sq : std::array<std::array<double, 2>, 3>{{{0.5, 0.0}, {0.5, 0.5}, {0.0, 0.5}}}) {
      for (size_t i = 0; i < rx.size(); ++i) {
        for (size_t j = 0; j < rx.size(); ++j) {
          evaluate(sq[0] + 0.5 * rx[i], sq[1] + 0.5 * rx[j], w.data());
          const double wt = 0.25 * rw[i] * rw[j];
          for (size_t a = 0; a < kk; ++a) {
            const double fa = wt * w[a];
            if (fa == 0.0) continue;
            for (size_t b = 0; b < kk; ++b) {
              const double fab = fa * w[kk + b];
              if (fab == 0.0) continue;
              double* dst = &u[(a * kk + b) * kk];
              for (size_t c = 0; c < kk; ++c) dst[c] += fab * w[2 * kk + c];
            }
          }
        }
      }
    }
    // Ring n is ring 1 with every index transformed by A^(n-1): sum by doubling,
    // S <- S + (P x P x P) S, P <- P^2.
    auto transform = [&](const RowMatrix& p, const std::vector<double>& in) {
      std::vector<double> t1(in.size(), 0.0), t2(in.size(), 0.0);
      for (size_t a = 0; a < kk; ++a) {  // index 1
        for (size_t i = 0; i < kk; ++i) {
          const double pai = p(static_cast<Eigen::Index>(a), static_cast<Eigen::Index>(i));
          if (pai == 0.0) continue;
          for (size_t bc = 0; bc < kk * kk; ++bc) t1[i * kk * kk + bc] += pai * in[a * kk * kk + bc];
        }
      }
      for (size_t i = 0; i < kk; ++i) {  // index 2
        for (size_t b = 0; b < kk; ++b) {
          for (size_t j = 0; j < kk; ++j) {
            const double pbj = p(static_cast<Eigen::Index>(b), static_cast<Eigen::Index>(j));
            if (pbj == 0.0) continue;
            for (size_t c = 0; c < kk; ++c) t2[(i * kk + j) * kk + c] += pbj * t1[(i * kk + b) * kk + c];
          }
        }
      }
      std::fill(t1.begin(), t1.end(), 0.0);
      const Eigen::MatrixXd pm = p;
      for (size_t ij = 0; ij < kk * kk; ++ij) {  // index 3
        const Eigen::Map<const Eigen::RowVectorXd> src(&t2[ij * kk], k);
        Eigen::Map<Eigen::RowVectorXd>(&t1[ij * kk], k) = src * pm;
      }
      return t1;
    };
    RowMatrix power = subdivision_;
    double total = 0.0;
    for (double x : u) total += std::abs(x);
    for (int doubling = 0; doubling < 12; ++doubling) {
      const std::vector<double> added = transform(power, u);
      double size = 0.0;
      for (size_t i = 0; i < u.size(); ++i) {
        u[i] += added[i];
        size += std::abs(added[i]);
      }
      if (size < 1e-17 * total) break;
      power = (power * power).eval();
    }
    normal_tensor_ = std::move(u);
  });
  return normal_tensor_;
}

void EvConfig::normal_integral(int level, const RowMatrix& x, RowMatrix& out) const {
  const int k = size_;
  const auto kk = static_cast<size_t>(k);
  const std::vector<double>& u = normal_tensor();
  RowMatrix power = RowMatrix::Identity(k, k);
  for (int i = 0; i < level; ++i) power = (power * subdivision_).eval();
  const RowMatrix xl = power * x;  // the control points of the cell's own 1-ring
  // g_a = sum_bc U[a][b][c] x_b x x_c
  RowMatrix g = RowMatrix::Zero(k, 3);
  for (size_t a = 0; a < kk; ++a) {
    Eigen::RowVector3d sum = Eigen::RowVector3d::Zero();
    for (size_t b = 0; b < kk; ++b) {
      Eigen::RowVector3d inner = Eigen::RowVector3d::Zero();
      const double* row = &u[(a * kk + b) * kk];
      for (size_t c = 0; c < kk; ++c) inner += row[c] * xl.row(static_cast<Eigen::Index>(c));
      const Eigen::RowVector3d xb = xl.row(static_cast<Eigen::Index>(b));
      sum += xb.cross(inner);
    }
    g.row(static_cast<Eigen::Index>(a)) = sum;
  }
  out = power.transpose() * g;
}

const EvConfig* EvConfigStore::get(const std::vector<int32_t>& signature) {
  auto it = configs_.find(signature);
  if (it == configs_.end()) it = configs_.emplace(signature, EvConfig::build(signature)).first;
  return it->second.get();
}

// ---------------------------------------------------------------------------------------------
// FaceProgram

struct ProgramBuilder {
  using Param = std::array<double, 2>;
  struct Quad {
    int level = 0;
    Index face = 0;
    int subface = 0;
    std::array<Param, 4> corner;  // sub-face coordinates of the face's vertices, in its order
  };

  const LocalRefinement& local;
  EvConfigStore& configs;
  FaceProgram& program;

  void add_piece(const Quad& q, int origin, const EvConfig* config, RowMatrix matrix) {
    FaceProgram::Piece piece;
    piece.subface = q.subface;
    piece.umin = piece.vmin = 1.0;
    piece.umax = piece.vmax = 0.0;
    for (const Param& p : q.corner) {
      piece.umin = std::min(piece.umin, p[0]);
      piece.umax = std::max(piece.umax, p[0]);
      piece.vmin = std::min(piece.vmin, p[1]);
      piece.vmax = std::max(piece.vmax, p[1]);
    }
    const Param o = q.corner[static_cast<size_t>(origin)];
    const Param e1 = {q.corner[static_cast<size_t>((origin + 1) % 4)][0] - o[0],
                      q.corner[static_cast<size_t>((origin + 1) % 4)][1] - o[1]};
    const Param e2 = {q.corner[static_cast<size_t>((origin + 3) % 4)][0] - o[0],
                      q.corner[static_cast<size_t>((origin + 3) % 4)][1] - o[1]};
    const double l1 = e1[0] * e1[0] + e1[1] * e1[1], l2 = e2[0] * e2[0] + e2[1] * e2[1];
    piece.ou = o[0];
    piece.ov = o[1];
    piece.su = e1[0] / l1;
    piece.sv = e1[1] / l1;
    piece.tu = e2[0] / l2;
    piece.tv = e2[1] / l2;
    piece.config = config;
    piece.matrix = std::move(matrix);
    program.pieces_.push_back(std::move(piece));
  }

  // Splits q until every piece is a regular patch or an EvConfig; false if `max_level` is reached.
  bool process(const Quad& q, int max_level) {
    const Far::TopologyLevel& level = local.refiner->GetLevel(q.level);
    const RowMatrix& w = local.weights[static_cast<size_t>(q.level)];
    PatchGrid grid;
    if (regular_grid(level, q.face, 0, grid)) {
      add_piece(q, 0, nullptr, grid_rows(grid, w));
      return true;
    }
    auto fv = level.GetFaceVertices(q.face);
    int irregular = -1, count = 0;
    for (int c = 0; c < 4; ++c) {
      if (!is_regular_vertex(level, fv[c])) {
        irregular = c;
        ++count;
      }
    }
    if (count == 1) {
      Neighbourhood hood;
      if (extract_neighbourhood(level, q.face, irregular, hood)) {
        if (const EvConfig* config = configs.get(hood.signature)) {
          RowMatrix m(config->size(), w.cols());
          for (int i = 0; i < config->size(); ++i) m.row(i) = w.row(hood.vertices[static_cast<size_t>(i)]);
          add_piece(q, irregular, config, std::move(m));
          return true;
        }
      }
    }
    if (q.level >= max_level) return false;
    const Far::TopologyLevel& next = local.refiner->GetLevel(q.level + 1);
    const Index centre = level.GetFaceChildVertex(q.face);
    const Param mid = {0.25 * (q.corner[0][0] + q.corner[1][0] + q.corner[2][0] + q.corner[3][0]),
                       0.25 * (q.corner[0][1] + q.corner[1][1] + q.corner[2][1] + q.corner[3][1])};
    for (int c = 0; c < 4; ++c) {
      Quad child;
      child.level = q.level + 1;
      child.subface = q.subface;
      child.face = child_face_with(level, next, q.face, level.GetVertexChildVertex(fv[c]));
      if (child.face < 0) return false;
      auto cv = next.GetFaceVertices(child.face);
      for (int i = 0; i < 4; ++i) {
        const Index v = cv[i];
        bool found = v == centre;
        Param p = mid;
        for (int j = 0; j < 4 && !found; ++j) {
          const Param& a = q.corner[static_cast<size_t>(j)];
          const Param& b = q.corner[static_cast<size_t>((j + 1) % 4)];
          if (v == level.GetVertexChildVertex(fv[j])) {
            p = a;
            found = true;
          } else if (v == level.GetEdgeChildVertex(level.FindEdge(fv[j], fv[(j + 1) % 4]))) {
            p = {0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])};
            found = true;
          }
        }
        if (!found) return false;
        child.corner[static_cast<size_t>(i)] = p;
      }
      if (!process(child, max_level)) return false;
    }
    return true;
  }
};

std::unique_ptr<FaceProgram> FaceProgram::build(const std::vector<int32_t>& signature, EvConfigStore& configs) {
  const int n = signature[1];
  for (int max_level = 2; max_level <= 4; ++max_level) {
    LocalRefinement local = refine_local(signature, max_level);
    auto program = std::unique_ptr<FaceProgram>(new FaceProgram);
    program->size_ = local.base_size;
    ProgramBuilder builder{local, configs, *program};
    bool ok = true;
    if (n == 4) {
      ok = builder.process({0, 0, 0, {{{0, 0}, {1, 0}, {1, 1}, {0, 1}}}}, max_level);
    } else {
      // Sub-face k is the child at corner k: (0,0) there, (1,0) at the midpoint of edge k -> k+1,
      // (1,1) at the centre, (0,1) at the midpoint of edge k-1 -> k.
      const Far::TopologyLevel& l0 = local.refiner->GetLevel(0);
      const Far::TopologyLevel& l1 = local.refiner->GetLevel(1);
      auto fv = l0.GetFaceVertices(0);
      for (int k = 0; k < n && ok; ++k) {
        ProgramBuilder::Quad q;
        q.level = 1;
        q.subface = k;
        q.face = child_face_with(l0, l1, 0, l0.GetVertexChildVertex(fv[k]));
        if (q.face < 0) {
          ok = false;
          break;
        }
        const Index next_mid = l0.GetEdgeChildVertex(l0.FindEdge(fv[k], fv[(k + 1) % n]));
        const Index prev_mid = l0.GetEdgeChildVertex(l0.FindEdge(fv[(k + n - 1) % n], fv[k]));
        auto cv = l1.GetFaceVertices(q.face);
        for (int i = 0; i < 4; ++i) {
          const Index v = cv[i];
          q.corner[static_cast<size_t>(i)] = v == next_mid ? ProgramBuilder::Param{1, 0}
                                            : v == prev_mid ? ProgramBuilder::Param{0, 1}
                                            : v == l0.GetFaceChildVertex(0) ? ProgramBuilder::Param{1, 1}
                                                                             : ProgramBuilder::Param{0, 0};
        }
        ok = builder.process(q, max_level);
      }
    }
    if (ok) return program;
  }
  fail(ErrorCode::kUnprocessable,
       "cannot set up the exact limit surface of a face with this neighbourhood (is the mesh a manifold?)");
}

const FaceProgram::Piece& FaceProgram::piece_at(int subface, double u, double v) const {
  for (const Piece& p : pieces_) {
    if (p.subface == subface && u >= p.umin && u <= p.umax && v >= p.vmin && v <= p.vmax) return p;
  }
  fail(ErrorCode::kInternal, "no piece of the face contains the point");
}

void FaceProgram::to_subface(const Piece& piece, Eigen::Ref<RowMatrix> rows) {
  const double su = piece.su, sv = piece.sv, tu = piece.tu, tv = piece.tv;
  if (su == 1.0 && sv == 0.0 && tu == 0.0 && tv == 1.0) return;
  for (Eigen::Index i = 0; i + 5 < rows.rows(); i += 6) {
    for (Eigen::Index j = 0; j < rows.cols(); ++j) {
      const double fs = rows(i + 1, j), ft = rows(i + 2, j);
      const double fss = rows(i + 3, j), fst = rows(i + 4, j), ftt = rows(i + 5, j);
      rows(i + 1, j) = fs * su + ft * tu;
      rows(i + 2, j) = fs * sv + ft * tv;
      rows(i + 3, j) = fss * su * su + 2.0 * fst * su * tu + ftt * tu * tu;
      rows(i + 4, j) = fss * su * sv + fst * (su * tv + sv * tu) + ftt * tu * tv;
      rows(i + 5, j) = fss * sv * sv + 2.0 * fst * sv * tv + ftt * tv * tv;
    }
  }
}

void FaceProgram::evaluate(int subface, double u, double v, double* out, std::vector<double>& scratch) const {
  (void)scratch;
  const std::array<double, 2> uv = {u, v};
  thread_local RowMatrix rows;
  evaluate_many(subface, &uv, 1, rows);
  std::copy(rows.data(), rows.data() + rows.size(), out);
}

void FaceProgram::evaluate_many(int subface, const std::array<double, 2>* uvs, size_t count, RowMatrix& out) const {
  const int m = size_;
  out.resize(static_cast<Eigen::Index>(6 * count), m);
  // Each point's piece and, on an extraordinary piece, its ring and sub-patch.
  struct Point {
    const Piece* piece;
    EvConfig::Location at;
    size_t index;
  };
  std::vector<Point> points(count);
  for (size_t i = 0; i < count; ++i) {
    const Piece& p = piece_at(subface, uvs[i][0], uvs[i][1]);
    const double du = uvs[i][0] - p.ou, dv = uvs[i][1] - p.ov;
    const double s = std::clamp(p.su * du + p.sv * dv, 0.0, 1.0), t = std::clamp(p.tu * du + p.tv * dv, 0.0, 1.0);
    EvConfig::Location at;
    if (p.config) {
      at = EvConfig::locate(s, t);
    } else {
      at.a = s, at.b = t;
    }
    points[i] = {&p, at, i};
  }
  std::stable_sort(points.begin(), points.end(), [](const Point& x, const Point& y) {
    return x.piece != y.piece ? x.piece < y.piece
                              : (x.at.ring != y.at.ring ? x.at.ring < y.at.ring : x.at.patch < y.at.patch);
  });
  // One group: the points of one polynomial piece: (6 P x 16) basis rows times its 16 control
  // points (over the neighbourhood of an extraordinary piece, then over the local points).
  RowMatrix basis, local, result, deep;
  for (size_t first = 0; first < count;) {
    size_t last = first + 1;
    while (last < count && points[last].piece == points[first].piece && points[last].at.ring == points[first].at.ring &&
           points[last].at.patch == points[first].at.patch) {
      ++last;
    }
    const Piece& piece = *points[first].piece;
    const auto group = static_cast<Eigen::Index>(last - first);
    if (piece.config && points[first].at.ring == 0) {  // the extraordinary vertex itself
      local.resize(6, piece.config->size());
      piece.config->evaluate(0.0, 0.0, local.data());
      result.noalias() = local * piece.matrix;
      for (size_t i = first; i < last; ++i) out.middleRows(static_cast<Eigen::Index>(6 * points[i].index), 6) = result;
    } else {
      basis.resize(6 * group, 16);
      for (size_t i = first; i < last; ++i) {
        double* rows = basis.row(static_cast<Eigen::Index>(6 * (i - first))).data();
        if (piece.config) {
          EvConfig::basis_rows(points[i].at, rows);
        } else {
          double b[6][16];
          bspline_basis(points[i].at.a, points[i].at.b, b);
          std::copy(&b[0][0], &b[0][0] + 96, rows);
        }
      }
      if (piece.config) {
        local.noalias() = basis * piece.config->ring_points(points[first].at.ring, points[first].at.patch, deep);
        for (Eigen::Index r = 0; r < group; ++r) local.row(6 * r) += piece.config->limit_mask();
        result.noalias() = local * piece.matrix;
      } else {
        result.noalias() = basis * piece.matrix;
      }
      for (size_t i = first; i < last; ++i) {
        out.middleRows(static_cast<Eigen::Index>(6 * points[i].index), 6) =
            result.middleRows(static_cast<Eigen::Index>(6 * (i - first)), 6);
      }
    }
    for (size_t i = first; i < last; ++i) {
      to_subface(piece, out.middleRows(static_cast<Eigen::Index>(6 * points[i].index), 6));
    }
    first = last;
  }
}

const FaceProgram::Piece* FaceProgram::corner_piece(int subface, int corner, double size) const {
  static constexpr std::array<std::array<double, 2>, 4> kCorners = {{{0, 0}, {1, 0}, {1, 1}, {0, 1}}};
  const auto& c = kCorners[static_cast<size_t>(corner & 3)];
  for (const Piece& p : pieces_) {
    if (!p.config || p.subface != subface || p.ou != c[0] || p.ov != c[1]) continue;
    // A dyadic square inside the piece.
    const double h = size / (p.umax - p.umin);
    int e = 0;
    const double f = std::frexp(h, &e);
    return (h <= 1.0 && f == 0.5) ? &p : nullptr;
  }
  return nullptr;
}

bool FaceProgram::corner_rule(int subface, int corner, double size, int g, std::vector<double>& out) const {
  const Piece* p = corner_piece(subface, corner, size);
  if (!p) return false;
  const std::vector<double>& rule = p->config->corner_rule(g);
  std::vector<double> gx, gw;
  gauss_legendre_01(g, gx, gw);
  const double u0 = p->ou == 0.0 ? 0.0 : 1.0 - size, v0 = p->ov == 0.0 ? 0.0 : 1.0 - size;
  const double h = size / (p->umax - p->umin);
  auto nearest = [&](double x) {
    size_t best = 0;
    for (size_t i = 1; i < gx.size(); ++i) {
      if (std::abs(gx[i] - x) < std::abs(gx[best] - x)) best = i;
    }
    return best;
  };
  // The cell's Gauss points are the piece's, rotated.
  out.resize(static_cast<size_t>(g) * static_cast<size_t>(g));
  for (int j = 0; j < g; ++j) {
    for (int i = 0; i < g; ++i) {
      const double du = u0 + size * gx[static_cast<size_t>(i)] - p->ou, dv = v0 + size * gx[static_cast<size_t>(j)] - p->ov;
      const size_t si = nearest((p->su * du + p->sv * dv) / h), ti = nearest((p->tu * du + p->tv * dv) / h);
      out[static_cast<size_t>(i + g * j)] = rule[si + static_cast<size_t>(g) * ti];
    }
  }
  return true;
}

bool FaceProgram::corner_normal_integral(int subface, int corner, double size, const RowMatrix& x,
                                         RowMatrix& out) const {
  const Piece* p = corner_piece(subface, corner, size);
  if (!p) return false;
  int e = 0;
  (void)std::frexp(size / (p->umax - p->umin), &e);  // h = 2^(e-1)
  RowMatrix local;
  p->config->normal_integral(1 - e, p->matrix * x, local);
  // du dv = ds dt / |det|, x_u x x_v = det x_s x x_t: only the orientation of (s, t) remains.
  const double orientation = (p->su * p->tv - p->sv * p->tu) > 0.0 ? 1.0 : -1.0;
  out = orientation * (p->matrix.transpose() * local);
  return true;
}

const FaceProgram* FaceProgramStore::get(const std::vector<int32_t>& signature) {
  auto it = programs_.find(signature);
  if (it == programs_.end()) it = programs_.emplace(signature, FaceProgram::build(signature, configs_)).first;
  return it->second.get();
}

}  // namespace softshell::internal
