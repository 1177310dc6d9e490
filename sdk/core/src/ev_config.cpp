// EvConfig: exact evaluation on the neighbourhood of a quad with one extraordinary corner, and
// the quadrature support for the cell at that corner (see exact_limit.h).
#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <Eigen/QR>
#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/topologyRefiner.h>

#include "exact_limit.h"
#include "softshell/result.h"

namespace softshell::internal {
namespace {

using Index = Far::Index;

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
}  // namespace

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
    return nullptr;  // no limit mask: not a configuration we can evaluate exactly
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
    return nullptr;  // e.g. valence 2: no separated tangent plane modes
  }
  std::vector<double> w(6 * static_cast<size_t>(k));
  out->evaluate(0.75, 0.75, w.data());
  const Eigen::Map<const RowMatrix> wm(w.data(), 6, k);
  const Eigen::Matrix2d st = (wm.middleRows(1, 2) * chart).eval();
  const Eigen::Matrix2d at_corner = out->tangents_ * chart;
  if (st.determinant() * at_corner.determinant() < 0.0) out->tangents_.row(1) *= -1.0;
  if (!(std::abs(at_corner.determinant()) > 0.0)) {
    return nullptr;
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

}  // namespace softshell::internal
