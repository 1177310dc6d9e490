// The per-element kernels of the nonlinear shell (see nonlinear_element.h).
#include "nonlinear_element.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <type_traits>
#include <vector>

#include <Eigen/Dense>

#include "kirchhoff_love.h"
#include "quadrature.h"

namespace softshell::engine::internal::nonlinear_kernel {
namespace {

using V3 = Eigen::Vector3d;


// The point kernels work on several points at once: T is double (one point) or Lanes (four
// consecutive points; the AVX2 build does them in one register each, the baseline in two SSE2
// halves). The per-point arrays are stored by quantity (entry k of point q at k P + q), so that
// the four points' values are one load.
// (The helpers that pass Lanes by value are always inlined: no call crosses the two builds' ABIs.)
#pragma GCC diagnostic ignored "-Wpsabi"
using Lanes = double __attribute__((vector_size(32)));
using LaneMask = long __attribute__((vector_size(32)));
constexpr int kLanes = 4;

template <class T>
[[gnu::always_inline]] inline T load(const double* p) {
  if constexpr (std::is_same_v<T, double>) {
    return *p;
  } else {
    T v;
    std::memcpy(&v, p, sizeof(T));
    return v;
  }
}
template <class T>
[[gnu::always_inline]] inline void store(double* p, const T& v) {
  if constexpr (std::is_same_v<T, double>) {
    *p = v;
  } else {
    std::memcpy(p, &v, sizeof(T));
  }
}
[[gnu::always_inline]] inline double lane_sqrt(double x) { return std::sqrt(x); }
[[gnu::always_inline]] inline Lanes lane_sqrt(const Lanes& x) {
  return Lanes{std::sqrt(x[0]), std::sqrt(x[1]), std::sqrt(x[2]), std::sqrt(x[3])};
}
[[gnu::always_inline]] inline double lane_max(double a, double b) { return a > b ? a : b; }
[[gnu::always_inline]] inline Lanes lane_max(const Lanes& a, const Lanes& b) { return a > b ? a : b; }
[[gnu::always_inline]] inline double largest(double a) { return a; }
[[gnu::always_inline]] inline double largest(const Lanes& a) { return std::max(std::max(a[0], a[1]), std::max(a[2], a[3])); }
[[gnu::always_inline]] inline double sum(double a) { return a; }
[[gnu::always_inline]] inline double sum(const Lanes& a) { return (a[0] + a[1]) + (a[2] + a[3]); }
[[gnu::always_inline]] inline bool all(bool m) { return m; }
[[gnu::always_inline]] inline bool all(const LaneMask& m) { return (m[0] & m[1] & m[2] & m[3]) != 0; }

// A 3-vector of one quantity at T's points.
template <class T>
struct P3 {
  T x, y, z;
};
template <class T>
[[gnu::always_inline]] inline P3<T> operator+(const P3<T>& a, const P3<T>& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
template <class T>
[[gnu::always_inline]] inline P3<T> operator-(const P3<T>& a, const P3<T>& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
template <class T>
[[gnu::always_inline]] inline P3<T> operator-(const P3<T>& a) { return {-a.x, -a.y, -a.z}; }
template <class T>
[[gnu::always_inline]] inline P3<T> operator*(const T& s, const P3<T>& a) { return {s * a.x, s * a.y, s * a.z}; }
template <class T>
[[gnu::always_inline]] inline P3<T> operator/(const P3<T>& a, const T& s) { return {a.x / s, a.y / s, a.z / s}; }
template <class T>
[[gnu::always_inline]] inline T dot(const P3<T>& a, const P3<T>& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
template <class T>
[[gnu::always_inline]] inline P3<T> cross(const P3<T>& a, const P3<T>& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <class T>
[[gnu::always_inline]] inline bool finite(const P3<T>& a) {
  const T zero = (a.x - a.x) + (a.y - a.y) + (a.z - a.z);  // NaN unless every entry is finite
  return all(zero == zero);
}

// A point array stored by quantity: entry k of point q at base[k stride + q].
template <class T>
struct Column {
  const double* base;
  Eigen::Index stride;
  [[gnu::always_inline]] T at(int k) const { return load<T>(base + k * stride); }
  [[gnu::always_inline]] P3<T> vec(int k) const { return {at(k), at(k + 1), at(k + 2)}; }
  // Packed symmetric 3 x 3 (00 11 22 01 02 12) from entry k, times x.
  [[gnu::always_inline]] P3<T> sym_mul(int k, const P3<T>& x) const {
    const T s0 = at(k), s1 = at(k + 1), s2 = at(k + 2), s3 = at(k + 3), s4 = at(k + 4), s5 = at(k + 5);
    return {s0 * x.x + s3 * x.y + s4 * x.z, s3 * x.x + s1 * x.y + s5 * x.z, s4 * x.x + s5 * x.y + s2 * x.z};
  }
};
template <class T>
[[gnu::always_inline]] inline void store_vec(double* base, Eigen::Index stride, int k, const P3<T>& v) {
  store(base + k * stride, v.x);
  store(base + (k + 1) * stride, v.y);
  store(base + (k + 2) * stride, v.z);
}
// Row r of a values or coefficients array (axes 6P apart) at T's points.
template <class T>
[[gnu::always_inline]] inline P3<T> row(const double* base, Eigen::Index p, Eigen::Index axes, int r) {
  const double* b = base + r * p;
  return {load<T>(b), load<T>(b + axes), load<T>(b + 2 * axes)};
}
template <class T>
[[gnu::always_inline]] inline void store_row(double* base, Eigen::Index p, Eigen::Index axes, int r, const P3<T>& v) {
  double* b = base + r * p;
  store(b, v.x);
  store(b + axes, v.y);
  store(b + 2 * axes, v.z);
}

// Internal force coefficients at T's points (from point q: ref, values, state and coef point at
// q's entries): f_A = sum_d N_A,d c_d, c_0 the pressure force per unit pressure w (a1 x a2) when
// asked for. The displacement derivatives u,u u,v u,uu u,uv u,vv are values rows 1-5. `gradient`
// gathers |u,a|^2 / |A_a|^2. Returns false for a degenerate point.
template <class T>
[[gnu::always_inline]] inline bool point_forces(const double* ref, const double* values, double* state, double* coef,
                                                Eigen::Index p, double bending, bool pressure, T& energy, T& gradient) {
  const Eigen::Index axes = kRows * p;
  const Column<T> r{ref, p};
  const P3<T> A1 = r.vec(0), A2 = r.vec(3), A11 = r.vec(6), A12 = r.vec(9), A22 = r.vec(12);
  const P3<T> N0 = r.vec(15);
  const T J = r.at(18);
  const P3<T> T3 = J * N0;
  const P3<T> d1 = row<T>(values, p, axes, 1), d2 = row<T>(values, p, axes, 2), d11 = row<T>(values, p, axes, 3),
              d12 = row<T>(values, p, axes, 4), d22 = row<T>(values, p, axes, 5);
  gradient = lane_max(gradient, lane_max(dot(d1, d1) / dot(A1, A1), dot(d2, d2) / dot(A2, A2)));
  // Green-Lagrange strains [E11, E22, 2 E12] without forming a.a - A.A.
  const T half = T{} + 0.5;
  const P3<T> e{dot(A1, d1) + half * dot(d1, d1), dot(A2, d2) + half * dot(d2, d2), dot(A1, d2) + dot(d1, A2) + dot(d1, d2)};
  const P3<T> dt3 = cross(d1, A2) + cross(A1, d2) + cross(d1, d2);
  const P3<T> t3 = T3 + dt3;
  const T j = lane_sqrt(dot(t3, t3));
  const T small = 1e-12 * J;
  if (!all(j > small) || !all(j - j == T{})) return false;
  const P3<T> n = t3 / j;
  // n - N = dt3 / j + N (J - j) / j, with J - j = (J^2 - j^2) / (J + j).
  const T j_drop = -(2.0 * dot(T3, dt3) + dot(dt3, dt3)) / (J + j);
  const P3<T> dn = dt3 / j + (j_drop / j) * N0;
  // Curvature change B_ab - b_ab = -(A_ab . (n - N) + u,ab . n).
  const P3<T> k{-(dot(A11, dn) + dot(d11, n)), -(dot(A22, dn) + dot(d22, n)), -2.0 * (dot(A12, dn) + dot(d12, n))};
  const P3<T> nm = r.sym_mul(19, e), mm = (T{} + bending) * r.sym_mul(19, k);
  if (!finite(nm) || !finite(mm)) return false;
  energy += half * (dot(e, nm) + dot(k, mm));
  const P3<T> a1 = A1 + d1, a2 = A2 + d2, a11 = A11 + d11, a12 = A12 + d12, a22 = A22 + d22;
  const P3<T> h = mm.x * a11 + mm.y * a22 + (2.0 * mm.z) * a12;
  const P3<T> g = (h - dot(n, h) * n) / j;
  if (pressure) store_row(coef, p, axes, 0, r.at(25) * t3);
  store_row(coef, p, axes, 1, nm.x * a1 + nm.z * a2 - cross(a2, g));
  store_row(coef, p, axes, 2, nm.z * a1 + nm.y * a2 - cross(g, a1));
  store_row(coef, p, axes, 3, -(mm.x * n));
  store_row(coef, p, axes, 4, -((2.0 * mm.z) * n));
  store_row(coef, p, axes, 5, -(mm.y * n));
  if (state) {
    store_vec(state, p, 0, a1);
    store_vec(state, p, 3, a2);
    store_vec(state, p, 6, a11);
    store_vec(state, p, 9, a12);
    store_vec(state, p, 12, a22);
    store_vec(state, p, 15, n);
    store(state + 18 * p, j);
    store_vec(state, p, 19, nm);
    store_vec(state, p, 22, mm);
    store_vec(state, p, 25, h);
    store_vec(state, p, 28, g);
  }
  return true;
}

// The directional derivative of point_forces' coefficients (minus `pressure` times the pressure
// coefficient) for the direction's derivatives v,u v,v v,uu v,uv v,vv (values rows 1-5).
template <class T>
[[gnu::always_inline]] inline void point_tangent(const double* ref, const double* state, const double* values,
                                                 double* coef, Eigen::Index p, double bending, double pressure) {
  const Eigen::Index axes = kRows * p;
  const Column<T> r{ref, p}, s{state, p};
  const P3<T> a1 = s.vec(0), a2 = s.vec(3), a11 = s.vec(6), a12 = s.vec(9), a22 = s.vec(12), n = s.vec(15);
  const T j = s.at(18);
  const P3<T> nm = s.vec(19), mm = s.vec(22), h = s.vec(25), g = s.vec(28);
  const P3<T> v1 = row<T>(values, p, axes, 1), v2 = row<T>(values, p, axes, 2), v11 = row<T>(values, p, axes, 3),
              v12 = row<T>(values, p, axes, 4), v22 = row<T>(values, p, axes, 5);
  const P3<T> de{dot(a1, v1), dot(a2, v2), dot(a1, v2) + dot(a2, v1)};
  const P3<T> dt3 = cross(v1, a2) + cross(a1, v2);
  const T dj = dot(n, dt3);
  const P3<T> dn = (dt3 - dj * n) / j;
  const P3<T> dk{-(dot(v11, n) + dot(a11, dn)), -(dot(v22, n) + dot(a22, dn)), -2.0 * (dot(v12, n) + dot(a12, dn))};
  const P3<T> dnm = r.sym_mul(19, de), dmm = (T{} + bending) * r.sym_mul(19, dk);
  const P3<T> dh = dmm.x * a11 + dmm.y * a22 + (2.0 * dmm.z) * a12 + mm.x * v11 + mm.y * v22 + (2.0 * mm.z) * v12;
  const T hn = dot(n, h);
  const P3<T> dg = (dh - hn * dn - (dot(dn, h) + dot(n, dh)) * n) / j - (dj / j) * g;
  if (pressure != 0.0) store_row(coef, p, axes, 0, (-pressure * r.at(25)) * dt3);
  store_row(coef, p, axes, 1, dnm.x * a1 + dnm.z * a2 + nm.x * v1 + nm.z * v2 - cross(v2, g) - cross(a2, dg));
  store_row(coef, p, axes, 2, dnm.z * a1 + dnm.y * a2 + nm.z * v1 + nm.y * v2 - cross(dg, a1) - cross(g, v1));
  store_row(coef, p, axes, 3, -(dmm.x * n + mm.x * dn));
  store_row(coef, p, axes, 4, -((2.0 * dmm.z) * n + (2.0 * mm.z) * dn));
  store_row(coef, p, axes, 5, -(dmm.y * n + mm.y * dn));
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

// The Bernstein pieces' passes, the bulk of a pass over the points, with the sums kept in
// registers: 16 coefficients x 3 axes are 12 Lanes. On 3 x 3 and 4 x 4 cells they go by sum
// factorization (tensor_values, tensor_transpose); other cells use `basis`, the unit cell's
// bicubic basis at the cell's n points, by coefficient (column k: rows r n + q) for the forward
// pass and by point (row r n + q: the 16 values) for the transposed one.

// Derivative row r's factor on a cell of edge `size` (the basis is of the unit cell).
[[gnu::always_inline]] inline double row_scale(int r, double size) {
  return kOrder[r] == 0 ? 1.0 : kOrder[r] == 1 ? 1.0 / size : 1.0 / (size * size);
}

// y (3 axes x 16) = the piece's Bernstein coefficients of u: y[a][k] = sum_A w(k, A) u(A, a).
[[gnu::always_inline]] inline void bernstein_coefficients(const double* __restrict w, Eigen::Index w_rows,
                                                          Eigen::Index m, const double* __restrict u, double* y) {
  Lanes s[3][4] = {};
  for (Eigen::Index a = 0; a < m; ++a) {
    const double* __restrict col = w + a * w_rows;
    const double u0 = u[a], u1 = u[m + a], u2 = u[2 * m + a];
    _Pragma("GCC unroll 16")
    for (int i = 0; i < 4; ++i) {
      const Lanes c = load<Lanes>(col + 4 * i);
      s[0][i] += c * u0;
      s[1][i] += c * u1;
      s[2][i] += c * u2;
    }
  }
  _Pragma("GCC unroll 16")
  for (int ax = 0; ax < 3; ++ax) {
    _Pragma("GCC unroll 16")
    for (int i = 0; i < 4; ++i) store(y + 16 * ax + 4 * i, s[ax][i]);
  }
}

// Sum factorization: the bicubic basis at a g x g tensor grid is a product of 1-D cubics, so the
// sums over the 16 coefficients split into two sums of 4, one per direction: about 2.5 times
// fewer products than by the 16 x g^2 table, an evaluation of catmark_righthanded's model 10-12%
// faster, a tangent product 8-10%. Vectors run over the g points of a grid row (the fourth lane
// is zero on a 3 x 3 cell).
struct CubicTable {
  // B_a^(order)(t_i) of the unit interval's g Gauss points: by point [order][a][i] and by
  // coefficient [order][i][a], zero past g.
  alignas(32) double over_points[3][4][4];
  alignas(32) double over_coefficients[3][4][4];
};
// g = 3 or 4 (built once; thread-safe).
const CubicTable& cubic_table(int g) {
  static const std::array<CubicTable, 2> tables = [] {
    std::array<CubicTable, 2> out{};
    for (int points : {3, 4}) {
      std::vector<double> gp, gw;
      gauss_legendre_01(points, gp, gw);
      CubicTable& t = out[static_cast<size_t>(points - 3)];
      for (int i = 0; i < points; ++i) {
        const double x = gp[static_cast<size_t>(i)], y = 1.0 - x;
        const double b[3][4] = {{y * y * y, 3 * x * y * y, 3 * x * x * y, x * x * x},
                                {-3 * y * y, 3 * y * y - 6 * x * y, 6 * x * y - 3 * x * x, 3 * x * x},
                                {6 * y, 18 * x - 12, 6 - 18 * x, 6 * x}};
        for (int order = 0; order < 3; ++order) {
          for (int a = 0; a < 4; ++a) {
            t.over_points[order][a][i] = b[order][a];
            t.over_coefficients[order][i][a] = b[order][a];
          }
        }
      }
    }
    return out;
  }();
  return tables[static_cast<size_t>(g - 3)];
}
constexpr int kOrderU[kRows] = {0, 1, 0, 2, 1, 0}, kOrderV[kRows] = {0, 0, 1, 0, 1, 2};

// values rows first_row <= r < end_row at a G x G cell's points from its coefficients y.
template <int G>
[[gnu::always_inline]] inline void tensor_values(const double* __restrict y, double size, Eigen::Index first,
                                                 Eigen::Index p, int first_row, int end_row,
                                                 double* __restrict values) {
  const CubicTable& table = cubic_table(G);
  const Eigen::Index axes = kRows * p;
  // Along u first: t[du][bv][axis] over the grid row's points.
  bool used[3] = {false, false, false};
  for (int r = first_row; r < end_row; ++r) used[kOrderU[r]] = true;
  Lanes t[3][4][3];
  for (int du = 0; du < 3; ++du) {
    if (!used[du]) continue;
    _Pragma("GCC unroll 16")
    for (int bv = 0; bv < 4; ++bv) {
      Lanes s0{}, s1{}, s2{};
      _Pragma("GCC unroll 16")
      for (int bu = 0; bu < 4; ++bu) {
        const Lanes b = load<Lanes>(table.over_points[du][bu]);
        s0 += b * y[bu + 4 * bv];
        s1 += b * y[16 + bu + 4 * bv];
        s2 += b * y[32 + bu + 4 * bv];
      }
      t[du][bv][0] = s0, t[du][bv][1] = s1, t[du][bv][2] = s2;
    }
  }
  // Then along v, at each grid row j.
  for (int r = first_row; r < end_row; ++r) {
    const double scale = row_scale(r, size);
    const int du = kOrderU[r], dv = kOrderV[r];
    double* __restrict out = values + r * p + first;
    for (int j = 0; j < G; ++j) {
      _Pragma("GCC unroll 16")
      for (int ax = 0; ax < 3; ++ax) {
        Lanes v{};
        _Pragma("GCC unroll 16")
        for (int bv = 0; bv < 4; ++bv) v += table.over_points[dv][bv][j] * t[du][bv][ax];
        v *= scale;
        double* __restrict at = out + ax * axes + G * j;
        if constexpr (G == 4) {
          store(at, v);
        } else {
          _Pragma("GCC unroll 16")
          for (int i = 0; i < G; ++i) at[i] = v[i];
        }
      }
    }
  }
}

// f (m x 3) += a G x G cell's share of W^T coef over rows first_row <= r < end_row.
template <int G>
[[gnu::always_inline]] inline void tensor_transpose(const double* __restrict w, Eigen::Index w_rows, Eigen::Index m,
                                                    double size, Eigen::Index first, Eigen::Index p,
                                                    int first_row, int end_row, const double* __restrict coef,
                                                    double* __restrict f) {
  const CubicTable& table = cubic_table(G);
  const Eigen::Index axes = kRows * p;
  // Along v first: s[du][bv][axis] over a grid row's points.
  Lanes s[3][4][3] = {};
  bool used[3] = {false, false, false};
  for (int r = first_row; r < end_row; ++r) {
    const double scale = row_scale(r, size);
    const int du = kOrderU[r], dv = kOrderV[r];
    used[du] = true;
    const double* __restrict c = coef + r * p + first;
    for (int j = 0; j < G; ++j) {
      _Pragma("GCC unroll 16")
      for (int ax = 0; ax < 3; ++ax) {
        const double* __restrict at = c + ax * axes + G * j;
        Lanes cj;
        if constexpr (G == 4) {
          cj = load<Lanes>(at);
        } else {
          cj = Lanes{at[0], at[1], at[2], 0.0};
        }
        cj *= scale;
        _Pragma("GCC unroll 16")
        for (int bv = 0; bv < 4; ++bv) s[du][bv][ax] += table.over_points[dv][bv][j] * cj;
      }
    }
  }
  // Then along u: z[axis][bv] over the coefficients bu (k = bu + 4 bv, as the basis's columns).
  Lanes z[3][4] = {};
  for (int du = 0; du < 3; ++du) {
    if (!used[du]) continue;
    _Pragma("GCC unroll 16")
    for (int i = 0; i < G; ++i) {
      const Lanes b = load<Lanes>(table.over_coefficients[du][i]);
      _Pragma("GCC unroll 16")
      for (int bv = 0; bv < 4; ++bv) {
        _Pragma("GCC unroll 16")
        for (int ax = 0; ax < 3; ++ax) z[ax][bv] += b * s[du][bv][ax][i];
      }
    }
  }
  for (Eigen::Index a = 0; a < m; ++a) {
    const double* __restrict col = w + a * w_rows;
    Lanes s0{}, s1{}, s2{};
    _Pragma("GCC unroll 16")
    for (int i = 0; i < 4; ++i) {
      const Lanes ci = load<Lanes>(col + 4 * i);
      s0 += ci * z[0][i];
      s1 += ci * z[1][i];
      s2 += ci * z[2][i];
    }
    f[a] += sum(s0);
    f[m + a] += sum(s1);
    f[2 * m + a] += sum(s2);
  }
}

// values = W u for one piece's points, rows first_row <= r < end_row (u: m x 3, column-major).
[[gnu::always_inline]] inline void piece_times(const double* __restrict w, Eigen::Index w_rows, double size,
                                               const double* __restrict bernstein, Eigen::Index first,
                                               Eigen::Index n, Eigen::Index p, Eigen::Index m, int first_row,
                                               int end_row, const double* __restrict u, double* __restrict values) {
  const Eigen::Index stride = kRows * p;
  if (size > 0.0 && (n == 16 || n == 9)) {
    double y[48];
    bernstein_coefficients(w, w_rows, m, u, y);
    if (n == 16) {
      tensor_values<4>(y, size, first, p, first_row, end_row, values);
    } else {
      tensor_values<3>(y, size, first, p, first_row, end_row, values);
    }
    return;
  }
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
  if (size > 0.0 && n == 16) {
    tensor_transpose<4>(w, w_rows, m, size, first, p, first_row, end_row, coef, f);
    return;
  }
  if (size > 0.0 && n == 9) {
    tensor_transpose<3>(w, w_rows, m, size, first, p, first_row, end_row, coef, f);
    return;
  }
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
                                  Eigen::Index m, const double* u, const double* reference, double bending,
                                  double* state, bool pressure, double* values, double* coef, double* force,
                                  double* pressure_force, double& energy, double& gradient) {
  for (size_t i = 0; i < count; ++i) {
    const PieceView& pc = pieces[i];
    piece_times(pc.w, pc.w_rows, pc.size, pc.basis_by_coefficient, pc.first, pc.points, p, m, 1, kRows, u, values);
  }
  Lanes lanes_energy{}, lanes_gradient{};
  double point_energy = 0.0, point_gradient = 0.0;
  Eigen::Index q = 0;
  for (; q + kLanes <= p; q += kLanes) {
    if (!point_forces<Lanes>(reference + q, values + q, state ? state + q : nullptr, coef + q, p, bending, pressure, lanes_energy, lanes_gradient)) {
      return false;
    }
  }
  for (; q < p; ++q) {
    if (!point_forces<double>(reference + q, values + q, state ? state + q : nullptr, coef + q, p, bending, pressure, point_energy, point_gradient)) {
      return false;
    }
  }
  energy += sum(lanes_energy) + point_energy;
  gradient = std::max(gradient, std::sqrt(std::max(largest(lanes_gradient), point_gradient)));
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
                                   Eigen::Index m, const double* v, const double* reference, double bending,
                                   const double* state, double pressure, double* values, double* coef, double* out) {
  for (size_t i = 0; i < count; ++i) {
    const PieceView& pc = pieces[i];
    piece_times(pc.w, pc.w_rows, pc.size, pc.basis_by_coefficient, pc.first, pc.points, p, m, 1, kRows, v, values);
  }
  Eigen::Index q = 0;
  for (; q + kLanes <= p; q += kLanes) point_tangent<Lanes>(reference + q, state + q, values + q, coef + q, p, bending, pressure);
  for (; q < p; ++q) point_tangent<double>(reference + q, state + q, values + q, coef + q, p, bending, pressure);
  const int first_row = pressure != 0.0 ? 0 : 1;  // the N rows only matter with a pressure
  for (size_t i = 0; i < count; ++i) {
    const PieceView& pc = pieces[i];
    piece_transpose_times(pc.w, pc.w_rows, pc.size, pc.basis_by_point, pc.first, pc.points, p, m, first_row, kRows, coef, out);
  }
}

namespace {

// C += A^T B by 4 x 4 and 8 x 4 tiles kept in registers: A (K x ma) and B (K x nb) stored by row
// (row k at a + k lda, at b + k ldb), ma and nb multiples of 4, C column-major (leading dimension
// ldc). `lower` (A and B the same): only the tiles on or below the diagonal.
[[gnu::always_inline]] inline void add_at_b(const double* __restrict a, Eigen::Index lda, const double* __restrict b,
                                            Eigen::Index ldb, Eigen::Index k_rows, Eigen::Index ma, Eigen::Index nb,
                                            double* __restrict c, Eigen::Index ldc, bool lower) {
  for (Eigen::Index col = 0; col < nb; col += 4) {
    Eigen::Index row = lower ? col : 0;
    for (; row + 8 <= ma; row += 8) {
      Lanes top[4] = {}, bottom[4] = {};
      for (Eigen::Index k = 0; k < k_rows; ++k) {
        const Lanes a0 = load<Lanes>(a + k * lda + row), a1 = load<Lanes>(a + k * lda + row + 4);
        const double* bk = b + k * ldb + col;
        _Pragma("GCC unroll 4")
        for (int j = 0; j < 4; ++j) {
          top[j] += a0 * bk[j];
          bottom[j] += a1 * bk[j];
        }
      }
      _Pragma("GCC unroll 4")
      for (int j = 0; j < 4; ++j) {
        double* cj = c + (col + j) * ldc + row;
        store(cj, load<Lanes>(cj) + top[j]);
        store(cj + 4, load<Lanes>(cj + 4) + bottom[j]);
      }
    }
    for (; row < ma; row += 4) {
      Lanes acc[4] = {};
      for (Eigen::Index k = 0; k < k_rows; ++k) {
        const Lanes a0 = load<Lanes>(a + k * lda + row);
        const double* bk = b + k * ldb + col;
        _Pragma("GCC unroll 4")
        for (int j = 0; j < 4; ++j) acc[j] += a0 * bk[j];
      }
      _Pragma("GCC unroll 4")
      for (int j = 0; j < 4; ++j) {
        double* cj = c + (col + j) * ldc + row;
        store(cj, load<Lanes>(cj) + acc[j]);
      }
    }
  }
}

Eigen::Index round_up4(Eigen::Index n) { return (n + 3) / 4 * 4; }

// A thread's scratch arrays for element tangent matrices, kept between elements.
struct TangentScratch {
  std::vector<double> strain_rows;  // 6P x round_up4(3m), by row
  std::vector<double> material;     // round_up4(3m)^2, column-major
  std::vector<double> channels;     // channels P x round_up4(m), by row
  std::vector<double> weighted;     // the same, the channels weighted by one geometric entry
  std::vector<double> pair;         // round_up4(m)^2, column-major
  std::vector<Eigen::Matrix3d> blocks;
};

}  // namespace

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
// The products over the points run in register tiles (add_at_b); the rest is per point.
SOFTSHELL_HOT void element_tangent_matrix(const Eigen::MatrixXd& basis, Eigen::Index p, Eigen::Index m,
                                          const double* reference, double bending, const double* state,
                                          double pressure, Eigen::MatrixXd& ke) {
  thread_local TangentScratch scratch;
  const int channels = pressure != 0.0 ? 4 : 3;
  const Eigen::Index dofs = 3 * m, wide = round_up4(dofs), mp = round_up4(m);
  std::vector<double>& rows = scratch.strain_rows;
  rows.assign(static_cast<size_t>(6 * p * wide), 0.0);
  scratch.channels.assign(static_cast<size_t>(channels * p * mp), 0.0);
  double* ch = scratch.channels.data();
  std::vector<Eigen::Matrix3d>& blocks = scratch.blocks;
  blocks.resize(static_cast<size_t>(channels * channels * p));
  auto block = [&](int c, int d, Eigen::Index q) -> Eigen::Matrix3d& {
    return blocks[static_cast<size_t>((c * channels + d) * p + q)];
  };
  Eigen::MatrixXd point_rows(6, dofs);
  Eigen::MatrixXd w6(6, m);
  SurfaceFrame frame;
  const double bending_weight = std::sqrt(bending);
  double ref[kRef], st[kState];  // the point's entries (stored by quantity)
  for (Eigen::Index q = 0; q < p; ++q) {
    for (int k = 0; k < kRef; ++k) ref[k] = reference[k * p + q];
    for (int k = 0; k < kState; ++k) st[k] = state[k * p + q];
    for (int d = 0; d < kRows; ++d) w6.row(d) = basis.row(d * p + q);
    frame.a1 = load3(st);
    frame.a2 = load3(st + 3);
    frame.a11 = load3(st + 6);
    frame.a12 = load3(st + 9);
    frame.a22 = load3(st + 12);
    frame.a3 = load3(st + 15);
    frame.j = st[18];
    Eigen::Matrix3d dm;
    dm << ref[19], ref[22], ref[23], ref[22], ref[20], ref[24], ref[23], ref[24], ref[21];
    const Eigen::LLT<Eigen::Matrix3d> factor(dm);
    const Eigen::Matrix3d um = factor.matrixU();
    weighted_strain_rows(w6, frame, um, bending_weight * um, point_rows);
    for (int r = 0; r < 6; ++r) {
      double* out = rows.data() + (6 * q + r) * wide;
      for (Eigen::Index col = 0; col < dofs; ++col) out[col] = point_rows(r, col);
    }
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
      block(3, 0, q) = -0.5 * pressure * ref[25] * e1;
      block(3, 1, q) = -0.5 * pressure * ref[25] * e2;
      block(0, 3, q) = block(3, 0, q).transpose();
      block(1, 3, q) = block(3, 1, q).transpose();
    }
    // Channel values: N,u, N,v, mN (, N).
    for (Eigen::Index a = 0; a < m; ++a) {
      ch[q * mp + a] = basis(p + q, a);
      ch[(p + q) * mp + a] = basis(2 * p + q, a);
      ch[(2 * p + q) * mp + a] = mm[0] * basis(3 * p + q, a) + mm[1] * basis(5 * p + q, a) + 2.0 * mm[2] * basis(4 * p + q, a);
      if (channels == 4) ch[(3 * p + q) * mp + a] = basis(q, a);
    }
  }
  // Material part: the lower tiles of rows^T rows.
  scratch.material.assign(static_cast<size_t>(wide * wide), 0.0);
  add_at_b(rows.data(), wide, rows.data(), wide, 6 * p, wide, wide, scratch.material.data(), wide, true);
  ke.resize(dofs, dofs);
  for (Eigen::Index col = 0; col < dofs; ++col) {
    for (Eigen::Index row = col; row < dofs; ++row) ke(row, col) = ke(col, row) = scratch.material[col * wide + row];
  }
  // Geometric part, per pair of axes (i, jj): ch^T Z with Z = sum_d diag(G_cd(i, jj)) ch_d.
  std::vector<double>& z = scratch.weighted;
  for (int i = 0; i < 3; ++i) {
    for (int jj = i; jj < 3; ++jj) {
      z.assign(scratch.channels.size(), 0.0);
      for (int c = 0; c < channels; ++c) {
        for (int d = 0; d < channels; ++d) {
          if ((c >= 2 && d >= 2) || (c == 3 && d == 2) || (c == 2 && d == 3)) continue;  // zero blocks
          for (Eigen::Index q = 0; q < p; ++q) {
            const double coef = block(c, d, q)(i, jj);
            double* out = z.data() + (c * p + q) * mp;
            const double* in = ch + (d * p + q) * mp;
            for (Eigen::Index a = 0; a < mp; ++a) out[a] += coef * in[a];
          }
        }
      }
      scratch.pair.assign(static_cast<size_t>(mp * mp), 0.0);
      add_at_b(ch, mp, z.data(), mp, channels * p, mp, mp, scratch.pair.data(), mp, false);
      const double* kij = scratch.pair.data();  // (a, b) at b mp + a
      for (Eigen::Index b = 0; b < m; ++b) {
        for (Eigen::Index a = 0; a < m; ++a) {
          ke(3 * a + i, 3 * b + jj) += kij[b * mp + a];
          if (jj != i) ke(3 * b + jj, 3 * a + i) += kij[b * mp + a];
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
