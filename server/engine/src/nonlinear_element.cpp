// The per-element kernels of the nonlinear shell (see nonlinear_element.h).
#include "nonlinear_element.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Dense>

#include "kirchhoff_love.h"
#include "quadrature.h"

namespace softshell::engine::internal::nonlinear_kernel {
namespace {

using V3 = Eigen::Vector3d;


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
    // By coefficient, so that the loop runs over the points (no sums across a vector).
    const Eigen::Index rows = kRows * n;
    for (int r = first_row; r < end_row; ++r) {
      const double scale = kOrder[r] == 0 ? 1.0 : kOrder[r] == 1 ? 1.0 / size : 1.0 / (size * size);
      double* __restrict d0 = values + r * p + first;
      double* __restrict d1 = d0 + stride;
      double* __restrict d2 = d0 + 2 * stride;
      for (Eigen::Index q = 0; q < n; ++q) d0[q] = d1[q] = d2[q] = 0.0;
      for (int k = 0; k < 16; ++k) {
        const double* __restrict col = bernstein + k * rows + r * n;  // coefficient k at the points, row r
        const double y0 = scale * y[k], y1 = scale * y[16 + k], y2 = scale * y[32 + k];
        for (Eigen::Index q = 0; q < n; ++q) {
          d0[q] += col[q] * y0;
          d1[q] += col[q] * y1;
          d2[q] += col[q] * y2;
        }
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

// [v]x, the matrix of v x .
Eigen::Matrix3d cross_matrix(const V3& v) {
  Eigen::Matrix3d c;
  c << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return c;
}

}  // namespace

// One element's internal forces (and pressure force per unit pressure) from its local
// displacements u (m x 3), with the per-point reference and state arrays of its points. Scratch
// arrays of 18P: values, coef. Returns false at a degenerate point.
SOFTSHELL_HOT bool element_forces(const PieceView* pieces, size_t count, Eigen::Index p,
                                  Eigen::Index m, const double* u, const double* reference, double* state,
                                  bool pressure, double* values, double* coef, double* force, double* pressure_force,
                                  double& energy, double& gradient) {
  const Eigen::Index stride = kRows * p;
  for (size_t i = 0; i < count; ++i) {
    const PieceView& pc = pieces[i];
    piece_times(pc.w, pc.w_rows, pc.size, pc.basis_by_coefficient, pc.first, pc.points, p, m, 1, kRows, u, values);
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
    piece_transpose_times(pc.w, pc.w_rows, pc.size, pc.basis_by_point, pc.first, pc.points, p, m, 1, kRows, coef, force);
    if (pressure) {  // the N rows: the pressure force per unit pressure
      piece_transpose_times(pc.w, pc.w_rows, pc.size, pc.basis_by_point, pc.first, pc.points, p, m, 0, 1, coef, pressure_force);
    }
  }
  return true;
}

// One element's tangent product for one vector (local values v, m x 3) into out (m x 3).
SOFTSHELL_HOT void element_tangent(const PieceView* pieces, size_t count, Eigen::Index p,
                                   Eigen::Index m, const double* v, const double* reference, const double* state,
                                   double pressure, double* values, double* coef, double* out) {
  const Eigen::Index stride = kRows * p;
  for (size_t i = 0; i < count; ++i) {
    const PieceView& pc = pieces[i];
    piece_times(pc.w, pc.w_rows, pc.size, pc.basis_by_coefficient, pc.first, pc.points, p, m, 1, kRows, v, values);
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
    piece_transpose_times(pc.w, pc.w_rows, pc.size, pc.basis_by_point, pc.first, pc.points, p, m, first_row, kRows, coef, out);
  }
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

}  // namespace softshell::engine::internal::nonlinear_kernel
