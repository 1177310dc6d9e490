#pragma once
// The per-element kernels of the nonlinear Kirchhoff-Love shell (private): internal forces,
// tangent products and element tangents over an element's quadrature points, given its basis
// (see nonlinear_shell.h for the model and the formulas). Plain pointers and sizes, so that the
// hot loops can be compiled for two instruction sets and picked at load time.

#include <cstddef>

#include <Eigen/Core>

namespace softshell::engine::internal::nonlinear_kernel {

// The per-point arrays of an element's P points are stored by quantity: entry k of point q at
// k P + q (so that consecutive points' values are one vector load).
// Per quadrature point, reference data (kRef doubles):
//   0 A1, 3 A2, 6 A11, 9 A12, 12 A22 (tangents and second derivatives), 15 N (unit normal),
//   18 J = |A1 x A2|, 19 membrane matrix dA t C (symmetric, packed 00 11 22 01 02 12), 25 parameter
//   weight (the Gauss weight times the cell area). The bending matrix is dA t^3/12 C: the membrane
//   matrix times `bending` = t^2 / 12, a parameter of the kernels.
constexpr int kRef = 26;
// Per quadrature point, deformed state (kState doubles):
//   0 a1, 3 a2, 6 a11, 9 a12, 12 a22, 15 n, 18 j, 19 membrane forces N (n11 n22 n12),
//   22 bending moments M (m11 m22 m12), 25 H = sum m_ab a_ab, 28 g = (I - n n^T) H / j.
constexpr int kState = 31;
// Derivative rows of an element's basis: 0 N, 1 ,u, 2 ,v, 3 ,uu, 4 ,uv, 5 ,vv.
constexpr int kRows = 6;

using V3 = Eigen::Vector3d;
// Always inlined: the kernels are compiled with their own options, which block plain inlining.
[[gnu::always_inline]] inline V3 load3(const double* p) { return V3(p[0], p[1], p[2]); }
[[gnu::always_inline]] inline void store3(double* p, const V3& v) {
  p[0] = v[0];
  p[1] = v[1];
  p[2] = v[2];
}
// Derivative order of basis row d (N; N,u, N,v; N,uu, N,uv, N,vv).
constexpr int kOrder[kRows] = {0, 1, 1, 2, 2, 2};

// What the per-element kernels need of an element (plain pointers, so the kernels can be
// compiled for two targets).
struct PieceView {
  const double* w;
  Eigen::Index w_rows, first, points;
  double size;               // > 0: w holds Bernstein coefficients on a cell of this edge length
  // Then the unit cell's bicubic basis at its points, 6 points x 16 (row d * points + q), stored
  // by coefficient (column-major) and by point (its transpose: the 16 values of a row contiguous).
  const double* basis_by_coefficient;
  const double* basis_by_point;
};

/// Internal forces (and the pressure force per unit pressure) of one element from its local
/// displacements u (m x 3, column-major), with the per-point reference and state arrays of its
/// points (the state is written, unless `state` is null). Scratch arrays values, coef of 18P.
/// Returns false at a degenerate point.
bool element_forces(const PieceView* pieces, size_t count, Eigen::Index p, Eigen::Index m,
                    const double* u, const double* reference, double bending, double* state, bool pressure,
                    double* values, double* coef, double* force, double* pressure_force, double& energy,
                    double& gradient);

/// out (m x 3) += the element's tangent product for local values v (m x 3).
void element_tangent(const PieceView* pieces, size_t count, Eigen::Index p, Eigen::Index m,
                     const double* v, const double* reference, double bending, const double* state, double pressure,
                     double* values, double* coef, double* out);

/// The element's tangent matrix (3m x 3m) from its full basis (6P x m, row d P + q).
void element_tangent_matrix(const Eigen::MatrixXd& basis, Eigen::Index p, Eigen::Index m, const double* reference,
                            double bending, const double* state, double pressure, Eigen::MatrixXd& ke);

/// The unit cell's bicubic Bernstein basis and its derivatives at the n x n Gauss points (row
/// d n^2 + j n + i, column a + 4 b for B_a(u) B_b(v)).
Eigen::MatrixXd bernstein_basis(int n);

}  // namespace softshell::engine::internal::nonlinear_kernel
