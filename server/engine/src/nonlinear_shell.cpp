#include "nonlinear_shell.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <Eigen/Dense>

#include "kirchhoff_love.h"
#include "parallel.h"
#include "quadrature.h"

namespace softshell::engine::internal {
namespace {

using V3 = Eigen::Vector3d;

// Per quadrature point, reference data (kRef doubles):
//   0 A1, 3 A2, 6 A11, 9 A12, 12 A22 (tangents and second derivatives), 15 A1 x A2, 18 J = |A1 x A2|,
//   19 N (unit normal), 22 membrane matrix dA t C, 28 bending matrix dA t^3/12 C (symmetric, packed
//   00 11 22 01 02 12), 34 parameter weight (the Gauss weight times the cell area).
constexpr int kRef = 35;
// Per quadrature point, deformed state (kState doubles):
//   0 a1, 3 a2, 6 a11, 9 a12, 12 a22, 15 n, 18 j, 19 membrane forces N (n11 n22 n12),
//   22 bending moments M (m11 m22 m12), 25 H = sum m_ab a_ab, 28 g = (I - n n^T) H / j.
constexpr int kState = 31;
// Derivative rows of an element's basis: 0 N, 1 ,u, 2 ,v, 3 ,uu, 4 ,uv, 5 ,vv.
constexpr int kRows = 6;

[[gnu::always_inline]] inline V3 load3(const double* p) { return V3(p[0], p[1], p[2]); }
[[gnu::always_inline]] inline void store3(double* p, const V3& v) {
  p[0] = v[0];
  p[1] = v[1];
  p[2] = v[2];
}
[[gnu::always_inline]] inline V3 sym_mul(const double* s, const V3& x) {
  return V3(s[0] * x[0] + s[3] * x[1] + s[4] * x[2], s[3] * x[0] + s[1] * x[1] + s[5] * x[2],
            s[4] * x[0] + s[5] * x[1] + s[2] * x[2]);
}

// Internal force coefficients of one point: f_A = sum_d N_A,d c[d] (c[0]: the pressure force per
// unit pressure, w (a1 x a2), when asked for). d = displacement derivatives u,u u,v u,uu u,uv u,vv.
// Returns false for a degenerate point.
[[gnu::always_inline]] inline bool point_forces(const double* ref, const V3* d, bool pressure, double* state, V3* c, double& energy,
                  double& gradient) {
  const V3 A1 = load3(ref), A2 = load3(ref + 3), A11 = load3(ref + 6), A12 = load3(ref + 9), A22 = load3(ref + 12);
  const V3 T3 = load3(ref + 15), N0 = load3(ref + 19);
  const double J = ref[18];
  const V3 &d1 = d[0], &d2 = d[1], &d11 = d[2], &d12 = d[3], &d22 = d[4];
  const V3 a1 = A1 + d1, a2 = A2 + d2, a11 = A11 + d11, a12 = A12 + d12, a22 = A22 + d22;
  gradient = std::max({gradient, d1.norm() / A1.norm(), d2.norm() / A2.norm()});
  // Green-Lagrange strains [E11, E22, 2 E12] without forming a.a - A.A.
  const V3 e(A1.dot(d1) + 0.5 * d1.squaredNorm(), A2.dot(d2) + 0.5 * d2.squaredNorm(),
             A1.dot(d2) + d1.dot(A2) + d1.dot(d2));
  const V3 dt3 = d1.cross(A2) + A1.cross(d2) + d1.cross(d2);
  const V3 t3 = T3 + dt3;
  const double j = t3.norm();
  if (!(j > 1e-12 * J) || !std::isfinite(j)) return false;
  const V3 n = t3 / j;
  // n - N = dt3 / j + N (J - j) / j, with J - j = (J^2 - j^2) / (J + j).
  const double j_drop = -(2.0 * T3.dot(dt3) + dt3.squaredNorm()) / (J + j);
  const V3 dn = dt3 / j + N0 * (j_drop / j);
  // Curvature change B_ab - b_ab = -(A_ab . (n - N) + u,ab . n).
  const V3 k(-(A11.dot(dn) + d11.dot(n)), -(A22.dot(dn) + d22.dot(n)), -2.0 * (A12.dot(dn) + d12.dot(n)));
  const V3 nm = sym_mul(ref + 22, e), mm = sym_mul(ref + 28, k);
  if (!nm.allFinite() || !mm.allFinite()) return false;
  energy += 0.5 * (e.dot(nm) + k.dot(mm));
  const V3 h = mm[0] * a11 + mm[1] * a22 + 2.0 * mm[2] * a12;
  const V3 g = (h - n * n.dot(h)) / j;
  c[0] = pressure ? V3(ref[34] * t3) : V3::Zero();
  c[1] = nm[0] * a1 + nm[2] * a2 - a2.cross(g);
  c[2] = nm[2] * a1 + nm[1] * a2 - g.cross(a1);
  c[3] = -mm[0] * n;
  c[4] = -2.0 * mm[2] * n;
  c[5] = -mm[1] * n;
  store3(state, a1);
  store3(state + 3, a2);
  store3(state + 6, a11);
  store3(state + 9, a12);
  store3(state + 12, a22);
  store3(state + 15, n);
  state[18] = j;
  store3(state + 19, nm);
  store3(state + 22, mm);
  store3(state + 25, h);
  store3(state + 28, g);
  return true;
}

// The directional derivative of the coefficients of point_forces (minus `pressure` times the
// pressure coefficient) for displacement derivatives v (v,u v,v v,uu v,uv v,vv).
[[gnu::always_inline]] inline void point_tangent(const double* ref, const double* state, double pressure, const V3* v, V3* c) {
  const V3 a1 = load3(state), a2 = load3(state + 3), a11 = load3(state + 6), a12 = load3(state + 9),
           a22 = load3(state + 12), n = load3(state + 15);
  const double j = state[18];
  const V3 nm = load3(state + 19), mm = load3(state + 22), h = load3(state + 25), g = load3(state + 28);
  const V3 &v1 = v[0], &v2 = v[1], &v11 = v[2], &v12 = v[3], &v22 = v[4];
  const V3 de(a1.dot(v1), a2.dot(v2), a1.dot(v2) + a2.dot(v1));
  const V3 dt3 = v1.cross(a2) + a1.cross(v2);
  const double dj = n.dot(dt3);
  const V3 dn = (dt3 - n * dj) / j;
  const V3 dk(-(v11.dot(n) + a11.dot(dn)), -(v22.dot(n) + a22.dot(dn)), -2.0 * (v12.dot(n) + a12.dot(dn)));
  const V3 dnm = sym_mul(ref + 22, de), dmm = sym_mul(ref + 28, dk);
  const V3 dh = dmm[0] * a11 + dmm[1] * a22 + 2.0 * dmm[2] * a12 + mm[0] * v11 + mm[1] * v22 + 2.0 * mm[2] * v12;
  const double hn = n.dot(h);
  const V3 dg = (dh - dn * hn - n * (dn.dot(h) + n.dot(dh))) / j - g * (dj / j);
  c[0] = -pressure * ref[34] * dt3;
  c[1] = dnm[0] * a1 + dnm[2] * a2 + nm[0] * v1 + nm[2] * v2 - v2.cross(g) - a2.cross(dg);
  c[2] = dnm[2] * a1 + dnm[1] * a2 + nm[2] * v1 + nm[1] * v2 - dg.cross(a1) - g.cross(v1);
  c[3] = -(dmm[0] * n + mm[0] * dn);
  c[4] = -2.0 * (dmm[2] * n + mm[2] * dn);
  c[5] = -(dmm[1] * n + mm[1] * dn);
}

// The hot loops are compiled twice and picked at load time: for x86-64-v3 (AVX2, FMA) where the
// CPU has it, and for the baseline. (The build targets the baseline; these loops are most of a
// nonlinear solve's time.)
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define SOFTSHELL_HOT __attribute__((target_clones("arch=x86-64-v3", "default"), optimize("vect-cost-model=dynamic")))
#else
#define SOFTSHELL_HOT
#endif

// Derivative order of basis row d (N; N,u, N,v; N,uu, N,uv, N,vv).
constexpr int kOrder[kRows] = {0, 1, 1, 2, 2, 2};

// Per-element point arrays below are "row r P + q" (r the derivative, q the point), with the
// three axes 6P apart.

// values = W u for one piece's points, rows first_row <= r < end_row (u: m x 3, column-major).
[[gnu::always_inline]] inline void piece_times(const double* __restrict w, Eigen::Index w_rows, double size,
                                               const double* __restrict bernstein, Eigen::Index first,
                                               Eigen::Index n, Eigen::Index p, Eigen::Index m, int first_row,
                                               int end_row, const double* __restrict u, double* __restrict values) {
  const Eigen::Index stride = kRows * p;
  if (size > 0.0) {
    // Bernstein coefficients of the patch: y = R u (16 x 3), then the unit-cell basis scaled to
    // the cell's size.
    double y[48];
    for (int k = 0; k < 48; ++k) y[k] = 0.0;
    for (Eigen::Index a = 0; a < m; ++a) {
      const double* __restrict col = w + a * w_rows;
      const double u0 = u[a], u1 = u[m + a], u2 = u[2 * m + a];
      for (int k = 0; k < 16; ++k) {
        y[k] += col[k] * u0;
        y[16 + k] += col[k] * u1;
        y[32 + k] += col[k] * u2;
      }
    }
    for (int r = first_row; r < end_row; ++r) {
      const double scale = kOrder[r] == 0 ? 1.0 : kOrder[r] == 1 ? 1.0 / size : 1.0 / (size * size);
      for (Eigen::Index q = 0; q < n; ++q) {
        const double* __restrict b = bernstein + 16 * (r * n + q);  // the basis at point q, row r
        double v0 = 0.0, v1 = 0.0, v2 = 0.0;
        for (int k = 0; k < 16; ++k) {
          const double bk = b[k];
          v0 += bk * y[k];
          v1 += bk * y[16 + k];
          v2 += bk * y[32 + k];
        }
        const Eigen::Index at = r * p + first + q;
        values[at] = scale * v0;
        values[stride + at] = scale * v1;
        values[2 * stride + at] = scale * v2;
      }
    }
    return;
  }
  for (int r = first_row; r < end_row; ++r) {
    double* __restrict d0 = values + r * p + first;
    double* __restrict d1 = d0 + stride;
    double* __restrict d2 = d0 + 2 * stride;
    for (Eigen::Index q = 0; q < n; ++q) d0[q] = d1[q] = d2[q] = 0.0;
    for (Eigen::Index a = 0; a < m; ++a) {
      const double* __restrict col = w + a * w_rows + r * n;
      const double u0 = u[a], u1 = u[m + a], u2 = u[2 * m + a];
      for (Eigen::Index q = 0; q < n; ++q) {
        d0[q] += col[q] * u0;
        d1[q] += col[q] * u1;
        d2[q] += col[q] * u2;
      }
    }
  }
}

// f (m x 3, column-major) += W^T coef over one piece's points, rows first_row <= r < end_row. Four
// partial sums keep the dot products vectorizable without reassociation.
[[gnu::always_inline]] inline void piece_transpose_times(const double* __restrict w, Eigen::Index w_rows, double size,
                                                         const double* __restrict bernstein, Eigen::Index first,
                                                         Eigen::Index n, Eigen::Index p, Eigen::Index m, int first_row,
                                                         int end_row, const double* __restrict coef,
                                                         double* __restrict f) {
  const Eigen::Index stride = kRows * p;
  if (size > 0.0) {
    double z[48];
    for (int k = 0; k < 48; ++k) z[k] = 0.0;
    for (int r = first_row; r < end_row; ++r) {
      const double scale = kOrder[r] == 0 ? 1.0 : kOrder[r] == 1 ? 1.0 / size : 1.0 / (size * size);
      for (Eigen::Index q = 0; q < n; ++q) {
        const Eigen::Index at = r * p + first + q;
        const double c0 = scale * coef[at], c1 = scale * coef[stride + at], c2 = scale * coef[2 * stride + at];
        const double* __restrict b = bernstein + 16 * (r * n + q);
        for (int k = 0; k < 16; ++k) {
          const double bk = b[k];
          z[k] += bk * c0;
          z[16 + k] += bk * c1;
          z[32 + k] += bk * c2;
        }
      }
    }
    for (Eigen::Index a = 0; a < m; ++a) {
      const double* __restrict col = w + a * w_rows;
      double s0 = 0.0, s1 = 0.0, s2 = 0.0;
      for (int k = 0; k < 16; ++k) {
        s0 += col[k] * z[k];
        s1 += col[k] * z[16 + k];
        s2 += col[k] * z[32 + k];
      }
      f[a] += s0;
      f[m + a] += s1;
      f[2 * m + a] += s2;
    }
    return;
  }
  for (int r = first_row; r < end_row; ++r) {
    const double* __restrict c0 = coef + r * p + first;
    const double* __restrict c1 = c0 + stride;
    const double* __restrict c2 = c0 + 2 * stride;
    const Eigen::Index blocks = n / 4 * 4;
    for (Eigen::Index a = 0; a < m; ++a) {
      const double* __restrict col = w + a * w_rows + r * n;
      double s0[4] = {0, 0, 0, 0}, s1[4] = {0, 0, 0, 0}, s2[4] = {0, 0, 0, 0};
      for (Eigen::Index q = 0; q < blocks; q += 4) {
        for (int l = 0; l < 4; ++l) {
          s0[l] += col[q + l] * c0[q + l];
          s1[l] += col[q + l] * c1[q + l];
          s2[l] += col[q + l] * c2[q + l];
        }
      }
      for (Eigen::Index q = blocks; q < n; ++q) {
        s0[0] += col[q] * c0[q];
        s1[0] += col[q] * c1[q];
        s2[0] += col[q] * c2[q];
      }
      f[a] += (s0[0] + s0[1]) + (s0[2] + s0[3]);
      f[m + a] += (s1[0] + s1[1]) + (s1[2] + s1[3]);
      f[2 * m + a] += (s2[0] + s2[1]) + (s2[2] + s2[3]);
    }
  }
}

// What the per-element kernels need of an element (plain pointers, so the kernels can be
// compiled for two targets).
struct PieceView {
  const double* w;
  Eigen::Index w_rows, first, points;
  double size;
};

// One element's internal forces (and pressure force per unit pressure) from its local
// displacements u (m x 3), with the per-point reference and state arrays of its points. Scratch
// arrays of 18P: values, coef. Returns false at a degenerate point.
SOFTSHELL_HOT bool element_forces(const PieceView* pieces, size_t count, const double* bernstein, Eigen::Index p,
                                  Eigen::Index m, const double* u, const double* reference, double* state,
                                  bool pressure, double* values, double* coef, double* force, double* pressure_force,
                                  double& energy, double& gradient) {
  const Eigen::Index stride = kRows * p;
  for (size_t i = 0; i < count; ++i) {
    const PieceView& pc = pieces[i];
    piece_times(pc.w, pc.w_rows, pc.size, bernstein, pc.first, pc.points, p, m, 1, kRows, u, values);
  }
  V3 d[5], c[kRows];
  for (Eigen::Index q = 0; q < p; ++q) {
    for (int r = 0; r < 5; ++r) {
      const Eigen::Index at = (r + 1) * p + q;
      d[r] = V3(values[at], values[stride + at], values[2 * stride + at]);
    }
    if (!point_forces(reference + kRef * q, d, pressure, state + kState * q, c, energy, gradient)) return false;
    for (int r = 0; r < kRows; ++r) {
      coef[r * p + q] = c[r][0];
      coef[stride + r * p + q] = c[r][1];
      coef[2 * stride + r * p + q] = c[r][2];
    }
  }
  for (size_t i = 0; i < count; ++i) {
    const PieceView& pc = pieces[i];
    piece_transpose_times(pc.w, pc.w_rows, pc.size, bernstein, pc.first, pc.points, p, m, 1, kRows, coef, force);
    if (pressure) {  // the N rows: the pressure force per unit pressure
      piece_transpose_times(pc.w, pc.w_rows, pc.size, bernstein, pc.first, pc.points, p, m, 0, 1, coef, pressure_force);
    }
  }
  return true;
}

// One element's tangent product for one vector (local values v, m x 3) into out (m x 3).
SOFTSHELL_HOT void element_tangent(const PieceView* pieces, size_t count, const double* bernstein, Eigen::Index p,
                                   Eigen::Index m, const double* v, const double* reference, const double* state,
                                   double pressure, double* values, double* coef, double* out) {
  const Eigen::Index stride = kRows * p;
  for (size_t i = 0; i < count; ++i) {
    const PieceView& pc = pieces[i];
    piece_times(pc.w, pc.w_rows, pc.size, bernstein, pc.first, pc.points, p, m, 1, kRows, v, values);
  }
  V3 d[5], c[kRows];
  for (Eigen::Index q = 0; q < p; ++q) {
    for (int r = 0; r < 5; ++r) {
      const Eigen::Index at = (r + 1) * p + q;
      d[r] = V3(values[at], values[stride + at], values[2 * stride + at]);
    }
    point_tangent(reference + kRef * q, state + kState * q, pressure, d, c);
    for (int r = 0; r < kRows; ++r) {
      coef[r * p + q] = c[r][0];
      coef[stride + r * p + q] = c[r][1];
      coef[2 * stride + r * p + q] = c[r][2];
    }
  }
  const int first_row = pressure != 0.0 ? 0 : 1;  // the N rows only matter with a pressure
  for (size_t i = 0; i < count; ++i) {
    const PieceView& pc = pieces[i];
    piece_transpose_times(pc.w, pc.w_rows, pc.size, bernstein, pc.first, pc.points, p, m, first_row, kRows, coef, out);
  }
}

// [v]x, the matrix of v x .
Eigen::Matrix3d cross_matrix(const V3& v) {
  Eigen::Matrix3d c;
  c << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return c;
}

// One element's tangent (3m x 3m, DOF 3A + i) at a state: the second derivative of the energy
// (minus `pressure` times the symmetric part of the pressure's load stiffness).
//  - material part: B^T D B with B the strain rows at the deformed frame (kirchhoff_love.h), as
//    one symmetric rank update over all points (as the linear model builds K);
//  - geometric part: sum over the points of (C (x) I3)^T G (C (x) I3), where C holds the basis
//    "channels" N,u, N,v and mN = m11 N,uu + m22 N,vv + 2 m12 N,uv (and N with a pressure), and
//    G the 3 x 3 blocks of the second variation of the strains times the stress resultants:
//      (u,u) = n11 I + [(e1n)(e1g)^T + (e1g)(e1n)^T] / j + (H.n / j^2) E1^T P E1, likewise (v,v);
//      (u,v) = n12 I + [(e1n)(e2g)^T + (e1g)(e2n)^T] / j + (H.n / j^2) E1^T P E2 + [g]x;
//      (mN,u) = -P E1 / j, (mN,v) = -P E2 / j;
//    with E1 = -[a2]x, E2 = [a1]x (the change of a1 x a2 per unit change of a1, a2), e1n = E1^T n,
//    e1g = E1^T g and so on, P = I - n n^T.
void element_tangent_matrix(const Eigen::MatrixXd& basis, Eigen::Index p, Eigen::Index m, const double* reference,
                            const double* state, double pressure, Eigen::MatrixXd& ke) {
  Eigen::MatrixXd g(6 * p, 3 * m), w6(6, m);
  SurfaceFrame frame;
  const int channels = pressure != 0.0 ? 4 : 3;
  Eigen::MatrixXd mn(p, m);                           // the mN channel
  std::vector<Eigen::Matrix3d> blocks(static_cast<size_t>(channels * channels * p), Eigen::Matrix3d::Zero());
  auto block = [&](int c, int d, Eigen::Index q) -> Eigen::Matrix3d& {
    return blocks[static_cast<size_t>((c * channels + d) * p + q)];
  };
  for (Eigen::Index q = 0; q < p; ++q) {
    const double* ref = reference + kRef * q;
    const double* st = state + kState * q;
    for (int d = 0; d < kRows; ++d) w6.row(d) = basis.row(d * p + q);
    frame.a1 = load3(st);
    frame.a2 = load3(st + 3);
    frame.a11 = load3(st + 6);
    frame.a12 = load3(st + 9);
    frame.a22 = load3(st + 12);
    frame.a3 = load3(st + 15);
    frame.j = st[18];
    Eigen::Matrix3d dm;
    dm << ref[22], ref[25], ref[26], ref[25], ref[23], ref[27], ref[26], ref[27], ref[24];
    const Eigen::LLT<Eigen::Matrix3d> factor(dm);
    const Eigen::Matrix3d um = factor.matrixU();
    const double bending = std::sqrt(ref[28] / ref[22]);  // (t^3 / 12) / t, the same for every entry
    weighted_strain_rows(w6, frame, um, bending * um, g.middleRows(6 * q, 6));
    // Geometric blocks.
    const V3 a1 = frame.a1, a2 = frame.a2, n = frame.a3;
    const double j = frame.j;
    const V3 nm = load3(st + 19), mm = load3(st + 22), h = load3(st + 25), gv = load3(st + 28);
    const Eigen::Matrix3d e1 = -cross_matrix(a2), e2 = cross_matrix(a1);
    const Eigen::Matrix3d proj = Eigen::Matrix3d::Identity() - n * n.transpose();
    const V3 e1n = e1.transpose() * n, e2n = e2.transpose() * n, e1g = e1.transpose() * gv, e2g = e2.transpose() * gv;
    const double hn = h.dot(n) / (j * j);
    block(0, 0, q) = nm[0] * Eigen::Matrix3d::Identity() + (e1n * e1g.transpose() + e1g * e1n.transpose()) / j +
                     hn * e1.transpose() * proj * e1;
    block(1, 1, q) = nm[1] * Eigen::Matrix3d::Identity() + (e2n * e2g.transpose() + e2g * e2n.transpose()) / j +
                     hn * e2.transpose() * proj * e2;
    block(0, 1, q) = nm[2] * Eigen::Matrix3d::Identity() + (e1n * e2g.transpose() + e1g * e2n.transpose()) / j +
                     hn * e1.transpose() * proj * e2 + cross_matrix(gv);
    block(1, 0, q) = block(0, 1, q).transpose();
    block(2, 0, q) = -proj * e1 / j;
    block(2, 1, q) = -proj * e2 / j;
    block(0, 2, q) = block(2, 0, q).transpose();
    block(1, 2, q) = block(2, 1, q).transpose();
    if (channels == 4) {  // -pressure w N_A (N,u_B E1 + N,v_B E2), symmetrized
      block(3, 0, q) = -0.5 * pressure * ref[34] * e1;
      block(3, 1, q) = -0.5 * pressure * ref[34] * e2;
      block(0, 3, q) = block(3, 0, q).transpose();
      block(1, 3, q) = block(3, 1, q).transpose();
    }
    mn.row(q) = mm[0] * basis.row(3 * p + q) + mm[1] * basis.row(5 * p + q) + 2.0 * mm[2] * basis.row(4 * p + q);
  }
  ke.setZero(3 * m, 3 * m);
  ke.selfadjointView<Eigen::Lower>().rankUpdate(g.transpose());
  ke.triangularView<Eigen::StrictlyUpper>() = ke.transpose();
  // Channel values per point: N,u, N,v, mN (, N).
  Eigen::MatrixXd ch(channels * p, m);
  ch.middleRows(0, p) = basis.middleRows(p, p);
  ch.middleRows(p, p) = basis.middleRows(2 * p, p);
  ch.middleRows(2 * p, p) = mn;
  if (channels == 4) ch.middleRows(3 * p, p) = basis.topRows(p);
  Eigen::MatrixXd z(channels * p, m), kij(m, m);
  Eigen::VectorXd coef(p);
  for (int i = 0; i < 3; ++i) {
    for (int jj = i; jj < 3; ++jj) {
      z.setZero();
      for (int c = 0; c < channels; ++c) {
        for (int d = 0; d < channels; ++d) {
          if ((c >= 2 && d >= 2) || (c == 3 && d == 2) || (c == 2 && d == 3)) continue;  // zero blocks
          for (Eigen::Index q = 0; q < p; ++q) coef[q] = block(c, d, q)(i, jj);
          z.middleRows(c * p, p).noalias() += coef.asDiagonal() * ch.middleRows(d * p, p);
        }
      }
      kij.noalias() = ch.transpose() * z;
      for (Eigen::Index b = 0; b < m; ++b) {
        for (Eigen::Index a = 0; a < m; ++a) {
          ke(3 * a + i, 3 * b + jj) += kij(a, b);
          if (jj != i) ke(3 * b + jj, 3 * a + i) += kij(a, b);
        }
      }
    }
  }
}

}  // namespace

template <class Fn>
void NonlinearShell::for_each_element(const Rule& rule, Fn&& fn) const {
  // Chunks of about the same number of points, so both threads finish together.
  constexpr size_t kPointsPerChunk = 1024;
  const int threads = rule.points < 2 * kPointsPerChunk ? 1 : resolve_threads(threads_);
  if (threads == 1) {
    for (size_t e = 0; e < rule.elements.size(); ++e) fn(e);
    return;
  }
  std::vector<size_t> starts{0};
  size_t points = 0;
  for (size_t e = 0; e < rule.elements.size(); ++e) {
    points += static_cast<size_t>(rule.elements[e].points);
    if (points >= kPointsPerChunk) {
      starts.push_back(e + 1);
      points = 0;
    }
  }
  if (starts.back() != rule.elements.size()) starts.push_back(rule.elements.size());
  parallel_for(0, static_cast<int64_t>(starts.size() - 1), threads, [&](int64_t c) {
    for (size_t e = starts[static_cast<size_t>(c)]; e < starts[static_cast<size_t>(c) + 1]; ++e) fn(e);
  });
}

// The unit cell's bicubic Bernstein basis and its derivatives at the n x n Gauss points (row
// d n^2 + j n + i, column a + 4 b for B_a(u) B_b(v)).
Eigen::MatrixXd bernstein_basis(int n) {
  std::vector<double> gp, gw;
  gauss_legendre_01(n, gp, gw);
  auto b = [](int a, int order, double t) {
    const double s = 1.0 - t;
    switch (order) {
      case 0: return a == 0 ? s * s * s : a == 1 ? 3 * t * s * s : a == 2 ? 3 * t * t * s : t * t * t;
      case 1: return a == 0 ? -3 * s * s : a == 1 ? 3 * s * s - 6 * t * s : a == 2 ? 6 * t * s - 3 * t * t : 3 * t * t;
      default: return a == 0 ? 6 * s : a == 1 ? 18 * t - 12 : a == 2 ? 6 - 18 * t : 6 * t;
    }
  };
  constexpr int kU[kRows] = {0, 1, 0, 2, 1, 0}, kV[kRows] = {0, 0, 1, 0, 1, 2};  // derivative orders
  const int nn = n * n;
  Eigen::MatrixXd out(kRows * nn, 16);
  for (int d = 0; d < kRows; ++d) {
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        for (int bv = 0; bv < 4; ++bv) {
          for (int bu = 0; bu < 4; ++bu) {
            out(d * nn + j * n + i, bu + 4 * bv) = b(bu, kU[d], gp[static_cast<size_t>(i)]) * b(bv, kV[d], gp[static_cast<size_t>(j)]);
          }
        }
      }
    }
  }
  return out;
}

void NonlinearShell::build_rule(const std::vector<Cell>& cells, int gauss, int threads, Rule& rule) const {
  const ShellModel& m = *model_;
  rule.elements.resize(cells.size());
  size_t points = 0;
  for (size_t c = 0; c < cells.size(); ++c) {
    rule.elements[c].first_point = points;
    rule.elements[c].points = static_cast<Eigen::Index>(cells[c].uvs.size());
    points += cells[c].uvs.size();
  }
  rule.points = points;
  rule.reference.assign(kRef * points, 0.0);
  rule.gauss = gauss;
  rule.bernstein = bernstein_basis(gauss);
  rule.bernstein_t = rule.bernstein.transpose();
  const Eigen::HouseholderQR<Eigen::MatrixXd> bernstein_qr(rule.bernstein);
  std::vector<double> gp, gw;
  gauss_legendre_01(gauss, gp, gw);
  const Eigen::SparseMatrix<double>& k = m.stiffness();
  const Material& mat = m.material();
  const double t = mat.thickness;
  parallel_for(0, static_cast<int64_t>(cells.size()), resolve_threads(threads), [&](int64_t ci) {
    const Cell& cell = cells[static_cast<size_t>(ci)];
    Element& e = rule.elements[static_cast<size_t>(ci)];
    const auto p = e.points;
    Eigen::MatrixXd bfr;  // 6P x m, rows 6q + d
    m.evaluator().face_stencils(cell.face, cell.subface, cell.uvs, e.indices, bfr);
    const auto mm = static_cast<Eigen::Index>(e.indices.size());
    Eigen::MatrixXd basis(kRows * p, mm);
    for (Eigen::Index q = 0; q < p; ++q) {
      for (int d = 0; d < kRows; ++d) basis.row(d * p + q) = bfr.row(kRows * q + d);
    }
    Eigen::MatrixX3d x(mm, 3);
    for (Eigen::Index a = 0; a < mm; ++a) {
      x.row(a) = m.mesh().positions()[static_cast<size_t>(e.indices[static_cast<size_t>(a)])].transpose();
    }
    const Eigen::MatrixX3d deriv = basis * x;
    SurfaceFrame frame;
    for (Eigen::Index q = 0; q < p; ++q) {
      // The same frame and material matrix the linear model was integrated with.
      if (!compute_frame(bfr.middleRows(kRows * q, kRows), x, mat.youngs_modulus, mat.poisson_ratio, frame)) {
        fail(ErrorCode::kUnprocessable, "nonlinear shell: the limit surface of face " + std::to_string(cell.face) +
                                            " is degenerate at a quadrature point");
      }
      double* ref = rule.reference.data() + kRef * (e.first_point + static_cast<size_t>(q));
      for (int d = 1; d < kRows; ++d) store3(ref + 3 * (d - 1), deriv.row(d * p + q).transpose());
      const V3 t3 = load3(ref).cross(load3(ref + 3));
      store3(ref + 15, t3);
      ref[18] = t3.norm();
      store3(ref + 19, t3 / t3.norm());
      const double weight = cell.weights[static_cast<size_t>(q)];
      const double da = weight * frame.j;
      const Eigen::Matrix3d& c = frame.material;
      const double packed[6] = {c(0, 0), c(1, 1), c(2, 2), c(0, 1), c(0, 2), c(1, 2)};
      for (int i = 0; i < 6; ++i) {
        ref[22 + i] = da * t * packed[i];
        ref[28 + i] = da * t * t * t / 12.0 * packed[i];
      }
      ref[34] = weight;
    }
    // Pieces: each run of gauss^2 points that is a square cell of the rule (points at u0 + s g_i,
    // v0 + s g_j, weights s^2 w_i w_j) and on which the basis is a bicubic polynomial to
    // round-off keeps 16 Bernstein coefficients per control point instead of its weights.
    const Eigen::Index cell_points = static_cast<Eigen::Index>(gauss) * gauss;
    auto take_weights = [&](Eigen::Index first, Eigen::Index count) {
      Piece piece;
      piece.first = first;
      piece.points = count;
      piece.w.resize(kRows * count, mm);
      for (int d = 0; d < kRows; ++d) piece.w.middleRows(d * count, count) = basis.middleRows(d * p + first, count);
      return piece;
    };
    if (p % cell_points != 0) {
      e.pieces.push_back(take_weights(0, p));
    } else {
      for (Eigen::Index first = 0; first < p; first += cell_points) {
        double area = 0.0;
        for (Eigen::Index q = first; q < first + cell_points; ++q) area += cell.weights[static_cast<size_t>(q)];
        const double size = std::sqrt(area);
        const double u0 = cell.uvs[static_cast<size_t>(first)][0] - size * gp[0];
        const double v0 = cell.uvs[static_cast<size_t>(first)][1] - size * gp[0];
        bool square = size > 0.0;
        for (Eigen::Index q = 0; q < cell_points && square; ++q) {
          const auto& uv = cell.uvs[static_cast<size_t>(first + q)];
          square = std::abs(uv[0] - (u0 + size * gp[static_cast<size_t>(q % gauss)])) <= 1e-12 &&
                   std::abs(uv[1] - (v0 + size * gp[static_cast<size_t>(q / gauss)])) <= 1e-12;
        }
        Piece piece = take_weights(first, cell_points);
        if (square) {
          // Fit on the unit cell: derivatives of order k carry size^k.
          Eigen::MatrixXd scaled = piece.w;
          for (int d = 0; d < kRows; ++d) scaled.middleRows(d * cell_points, cell_points) *= std::pow(size, kOrder[d]);
          const Eigen::MatrixXd coef = bernstein_qr.solve(scaled);
          const Eigen::MatrixXd back = rule.bernstein * coef;
          bool exact = true;
          const double overall = scaled.cwiseAbs().maxCoeff();
          for (int d = 0; d < kRows && exact; ++d) {
            const auto block = scaled.middleRows(d * cell_points, cell_points);
            const double top = std::max(block.cwiseAbs().maxCoeff(), 1e-6 * overall);
            exact = (back.middleRows(d * cell_points, cell_points) - block).cwiseAbs().maxCoeff() <= 1e-13 * top;
          }
          if (exact) {
            piece.w = coef;
            piece.size = size;
          }
        }
        e.pieces.push_back(std::move(piece));
      }
    }
    // Where each (a, b) block of the element lands in K's value array.
    e.offsets.resize(static_cast<size_t>(mm * mm));
    for (Eigen::Index bl = 0; bl < mm; ++bl) {
      const int col = 3 * e.indices[static_cast<size_t>(bl)];
      const int* begin = k.innerIndexPtr() + k.outerIndexPtr()[col];
      const int* end = k.innerIndexPtr() + k.outerIndexPtr()[col + 1];
      for (Eigen::Index al = 0; al < mm; ++al) {
        const int row = 3 * e.indices[static_cast<size_t>(al)];
        const int* it = std::lower_bound(begin, end, row);
        if (it == end || *it != row || end - it < 3 || it[2] != row + 2) {
          fail(ErrorCode::kInternal, "nonlinear shell: the stiffness pattern lacks an element's block");
        }
        e.offsets[static_cast<size_t>(al + mm * bl)] = static_cast<int32_t>(it - begin);
      }
    }
  });
}

std::shared_ptr<const NonlinearShell> NonlinearShell::build(std::shared_ptr<const ShellModel> model, int threads,
                                                            int jacobian_gauss_points) {
  if (!model) fail(ErrorCode::kInvalidArgument, "NonlinearShell needs a model");
  if (jacobian_gauss_points < 0 || jacobian_gauss_points > 10) {
    fail(ErrorCode::kInvalidArgument, "NonlinearShell: jacobian_gauss_points must be 0..10");
  }
  std::shared_ptr<NonlinearShell> shell(new NonlinearShell());
  shell->model_ = model;
  shell->threads_ = threads;
  const ShellModel& m = *model;
  // The model's rule: the runs of quadrature points on one (face, sub-face), in the order K was
  // built.
  std::vector<Cell> cells;
  const std::vector<QuadraturePoint>& quad = m.quadrature();
  for (size_t q = 0; q < quad.size(); ++q) {
    if (q == 0 || quad[q].point.face != quad[q - 1].point.face || quad[q].point.subface != quad[q - 1].point.subface) {
      cells.push_back(Cell{quad[q].point.face, quad[q].point.subface, {}, {}});
    }
    cells.back().uvs.push_back({quad[q].point.u, quad[q].point.v});
    cells.back().weights.push_back(quad[q].weight);
  }
  shell->build_rule(cells, m.options().quadrature.gauss_points, threads, shell->fine_);
  if (jacobian_gauss_points > 0) {
    std::vector<double> gp, gw;
    gauss_legendre_01(jacobian_gauss_points, gp, gw);
    for (Cell& cell : cells) {
      cell.uvs.clear();
      cell.weights.clear();
      for (size_t j = 0; j < gp.size(); ++j) {
        for (size_t i = 0; i < gp.size(); ++i) {
          cell.uvs.push_back({gp[i], gp[j]});
          cell.weights.push_back(gw[i] * gw[j]);
        }
      }
    }
    shell->build_rule(cells, jacobian_gauss_points, threads, shell->coarse_);
  }
  return shell;
}

Eigen::MatrixXd NonlinearShell::element_basis(const Rule& rule, const Element& e) {
  const auto p = e.points;
  Eigen::MatrixXd basis(kRows * p, static_cast<Eigen::Index>(e.indices.size()));
  for (const Piece& piece : e.pieces) {
    const Eigen::Index n = piece.points;
    if (piece.size > 0.0) {
      const Eigen::MatrixXd w = rule.bernstein * piece.w;
      for (int d = 0; d < kRows; ++d) {
        basis.middleRows(d * p + piece.first, n) = w.middleRows(d * n, n) / std::pow(piece.size, kOrder[d]);
      }
    } else {
      for (int d = 0; d < kRows; ++d) basis.middleRows(d * p + piece.first, n) = piece.w.middleRows(d * n, n);
    }
  }
  return basis;
}

size_t NonlinearShell::memory_bytes() const {
  size_t bytes = sizeof(*this);
  for (const Rule* rule : {&fine_, &coarse_}) {
    bytes += rule->reference.size() * sizeof(double);
    for (const Element& e : rule->elements) {
      bytes += sizeof(Element) + (e.indices.size() + e.offsets.size()) * sizeof(int32_t);
      for (const Piece& piece : e.pieces) bytes += sizeof(Piece) + static_cast<size_t>(piece.w.size()) * sizeof(double);
    }
  }
  return bytes;
}

bool NonlinearShell::evaluate(const Eigen::VectorXd& u, ShellState& state, bool with_pressure) const {
  return evaluate_rule(fine_, u, state, with_pressure);
}

bool NonlinearShell::evaluate_rule(const Rule& rule, const Eigen::VectorXd& u, ShellState& state,
                                   bool with_pressure) const {
  const int32_t ndof = num_dofs();
  if (u.size() != ndof) fail(ErrorCode::kInvalidArgument, "nonlinear shell: the displacement must have 3n entries");
  state.displacement = u;
  state.points.resize(kState * rule.points);
  const size_t ne = rule.elements.size();
  std::vector<Eigen::MatrixX3d> element_force(ne), element_pressure(with_pressure ? ne : 0);
  std::vector<double> element_energy(ne, 0.0), element_gradient(ne, 0.0);
  std::vector<char> element_ok(ne, 1);
  for_each_element(rule, [&](size_t ei) {
    const Element& e = rule.elements[ei];
    const auto p = e.points;
    const auto m = static_cast<Eigen::Index>(e.indices.size());
    Eigen::MatrixX3d local(m, 3);
    for (Eigen::Index a = 0; a < m; ++a) local.row(a) = u.segment<3>(3 * e.indices[static_cast<size_t>(a)]).transpose();
    std::vector<double> values(static_cast<size_t>(18 * p)), coef(static_cast<size_t>(18 * p));
    std::vector<PieceView> pieces;
    for (const Piece& pc : e.pieces) pieces.push_back({pc.w.data(), pc.w.rows(), pc.first, pc.points, pc.size});
    element_force[ei].setZero(m, 3);
    if (with_pressure) element_pressure[ei].setZero(m, 3);
    double energy = 0.0, gradient = 0.0;
    element_ok[ei] = element_forces(pieces.data(), pieces.size(), rule.bernstein_t.data(), p, m, local.data(),
                                    rule.reference.data() + kRef * e.first_point,
                                    state.points.data() + kState * e.first_point, with_pressure, values.data(),
                                    coef.data(), element_force[ei].data(),
                                    with_pressure ? element_pressure[ei].data() : nullptr, energy, gradient);
    element_energy[ei] = energy;
    element_gradient[ei] = gradient;
  });
  state.valid = std::all_of(element_ok.begin(), element_ok.end(), [](char ok) { return ok != 0; });
  state.energy = 0.0;
  state.max_gradient = ne ? *std::max_element(element_gradient.begin(), element_gradient.end()) : 0.0;
  state.internal_force.setZero(ndof);
  state.pressure_force.setZero(with_pressure ? ndof : 0);
  if (!state.valid) return false;
  for (size_t ei = 0; ei < ne; ++ei) {
    const Element& e = rule.elements[ei];
    state.energy += element_energy[ei];
    for (size_t a = 0; a < e.indices.size(); ++a) {
      state.internal_force.segment<3>(3 * e.indices[a]) += element_force[ei].row(static_cast<Eigen::Index>(a)).transpose();
      if (with_pressure) {
        state.pressure_force.segment<3>(3 * e.indices[a]) += element_pressure[ei].row(static_cast<Eigen::Index>(a)).transpose();
      }
    }
  }
  state.valid = std::isfinite(state.energy) && state.internal_force.allFinite() &&
                (!with_pressure || state.pressure_force.allFinite());
  return state.valid;
}

void NonlinearShell::tangent_product(const ShellState& state, double pressure, const Eigen::MatrixXd& v,
                                     Eigen::MatrixXd& out) const {
  const int32_t ndof = num_dofs();
  const Rule& rule = fine_;
  if (!state.valid || v.rows() != ndof || state.points.size() != kState * rule.points) {
    fail(ErrorCode::kInternal, "nonlinear shell: tangent product of a bad state");
  }
  const Eigen::Index cols = v.cols();
  std::vector<Eigen::MatrixXd> element_out(rule.elements.size());
  for_each_element(rule, [&](size_t ei) {
    const Element& e = rule.elements[ei];
    const auto p = e.points;
    const auto m = static_cast<Eigen::Index>(e.indices.size());
    Eigen::MatrixX3d local(m, 3);
    std::vector<double> values(static_cast<size_t>(18 * p)), coef(static_cast<size_t>(18 * p));
    std::vector<PieceView> pieces;
    for (const Piece& pc : e.pieces) pieces.push_back({pc.w.data(), pc.w.rows(), pc.first, pc.points, pc.size});
    Eigen::MatrixXd& result = element_out[ei];
    result.setZero(m, 3 * cols);
    for (Eigen::Index col = 0; col < cols; ++col) {
      for (Eigen::Index a = 0; a < m; ++a) local.row(a) = v.block<3, 1>(3 * e.indices[static_cast<size_t>(a)], col).transpose();
      element_tangent(pieces.data(), pieces.size(), rule.bernstein_t.data(), p, m, local.data(),
                      rule.reference.data() + kRef * e.first_point, state.points.data() + kState * e.first_point,
                      pressure, values.data(), coef.data(), result.data() + 3 * col * m);
    }
  });
  out.setZero(ndof, cols);
  for (size_t ei = 0; ei < rule.elements.size(); ++ei) {
    const Element& e = rule.elements[ei];
    const auto m = static_cast<Eigen::Index>(e.indices.size());
    for (Eigen::Index a = 0; a < m; ++a) {
      for (Eigen::Index c = 0; c < cols; ++c) {
        for (int i = 0; i < 3; ++i) out(3 * e.indices[static_cast<size_t>(a)] + i, c) += element_out[ei](a, 3 * c + i);
      }
    }
  }
}

void NonlinearShell::assemble_tangent(const ShellState& state, double pressure, Eigen::SparseMatrix<double>& out) const {
  assemble_rule(fine_, state, pressure, out);
}

bool NonlinearShell::assemble_jacobian(const ShellState& state, double pressure, Eigen::SparseMatrix<double>& out) const {
  if (!has_jacobian_rule()) {
    assemble_rule(fine_, state, pressure, out);
    return true;
  }
  ShellState coarse;
  if (!evaluate_rule(coarse_, state.displacement, coarse, false)) return false;
  assemble_rule(coarse_, coarse, pressure, out);
  return true;
}

void NonlinearShell::assemble_rule(const Rule& rule, const ShellState& state, double pressure,
                                   Eigen::SparseMatrix<double>& out) const {
  if (!state.valid || state.points.size() != kState * rule.points) {
    fail(ErrorCode::kInternal, "nonlinear shell: tangent of a bad state");
  }
  const Eigen::SparseMatrix<double>& k = model_->stiffness();
  out = k;  // the pattern; values overwritten below
  std::fill(out.valuePtr(), out.valuePtr() + out.nonZeros(), 0.0);
  std::vector<Eigen::MatrixXd> element_k(rule.elements.size());
  for_each_element(rule, [&](size_t ei) {
    const Element& e = rule.elements[ei];
    element_tangent_matrix(element_basis(rule, e), e.points, static_cast<Eigen::Index>(e.indices.size()),
                           rule.reference.data() + kRef * e.first_point, state.points.data() + kState * e.first_point,
                           pressure, element_k[ei]);
  });
  for (size_t ei = 0; ei < rule.elements.size(); ++ei) {
    const Element& e = rule.elements[ei];
    const auto m = static_cast<Eigen::Index>(e.indices.size());
    const Eigen::MatrixXd& ke = element_k[ei];
    for (Eigen::Index bl = 0; bl < m; ++bl) {
      for (int j = 0; j < 3; ++j) {
        double* column = out.valuePtr() + out.outerIndexPtr()[3 * e.indices[static_cast<size_t>(bl)] + j];
        for (Eigen::Index al = 0; al < m; ++al) {
          double* block = column + e.offsets[static_cast<size_t>(al + m * bl)];
          for (int i = 0; i < 3; ++i) block[i] += ke(3 * al + i, 3 * bl + j);
        }
      }
    }
  }
}

}  // namespace softshell::engine::internal
