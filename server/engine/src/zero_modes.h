#pragma once
// The zero-energy modes of a shell model (private to the engine).
//
// A displacement has no strain energy exactly when the limit surface moves rigidly: a connected
// smooth surface whose metric and curvature do not change moves as a rigid body, and rigid
// motions of the control points move the limit surface rigidly. So the zero-energy modes of a
// part are its six rigid modes plus the control displacements that leave its limit surface where
// it is: per axis, the null space of the scalar Gram matrix G_AB = sum_q w_q N_A(x_q) N_B(x_q)
// of the basis at the quadrature points. G depends only on the connectivity of the mesh, not on
// its thickness, material or size (a threshold on the stiffness would take the bending modes of a
// thin shell, energy ~ t^3 against the membrane's ~ t, for zero modes). Scaled to unit diagonal,
// its non-zero eigenvalues are bounded away from zero by the stability of the spline basis
// (measured on every shipped mesh: >= 7e-3; a single ghost-ringed face: 9e-6), so the null space
// is clear-cut for every part size.

#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "softshell/control_mesh.h"
#include "softshell/limit_evaluator.h"

namespace softshell::engine::internal {

/// The null space (orthonormal columns) of a symmetric positive semidefinite matrix with unit
/// diagonal whose non-zero eigenvalues are above 1e-8. A sparse Cholesky factor proves there is
/// none (the usual case: one factorization); otherwise matrices of at most `dense_limit` rows are
/// decomposed densely and larger ones by subspace iteration with the factor of a + sigma I.
/// Throws Exception(kInternal) if an eigenvalue is neither zero nor clearly positive.
Eigen::MatrixXd null_space_of_scaled_gram(const Eigen::SparseMatrix<double>& a, Eigen::Index dense_limit = 400);

/// The zero-energy modes of every part: `rigid` (3n x 6c, see ShellModel::rigid_modes) followed
/// by the motions that leave a part's limit surface where it is (orthonormal, orthogonal to the
/// rigid ones), from the scalar Gram matrix `gram` (n x n). `invisible` gets one `true` per extra
/// mode (by construction none moves the surface at a quadrature point).
void find_extra_zero_modes(const Eigen::SparseMatrix<double>& gram, const std::vector<int32_t>& component_of,
                           const Eigen::MatrixXd& rigid, Eigen::MatrixXd& modes, std::vector<bool>& invisible);

/// Throws Exception(kUnprocessable) if a part's limit surface falls apart into pieces that share
/// control points only through faces without a surface (a ghost layer, boundary "none"): such
/// pieces could move against each other without strain, a motion neither rigid nor invisible.
void check_surface_connected(const ControlMesh& mesh, const LimitEvaluator& evaluator,
                             const std::vector<int32_t>& component_of);

}  // namespace softshell::engine::internal
