#pragma once
// GMRES for the nonlinear solver's Newton steps (private): the tangent is applied matrix-free,
// the preconditioner is a constrained solve on a factored (possibly older) tangent. GMRES rather
// than CG because a follower pressure makes the tangent unsymmetric and a state past a
// buckling load makes it indefinite.

#include <functional>

#include <Eigen/Core>

namespace softshell::engine::internal {

struct KrylovResult {
  Eigen::VectorXd x;
  int iterations = 0;
  double relative_residual = 1.0;  // |b - B x| / |b| in the preconditioned norm
  bool converged = false;
};

/// Solves B x = b for B = (preconditioner o operator), given as `apply` (v -> B v), with b the
/// preconditioned right-hand side, until |b - B x| <= tolerance |b| or `max_iterations`.
KrylovResult gmres(const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& apply, const Eigen::VectorXd& b,
                   double tolerance, int max_iterations);

}  // namespace softshell::engine::internal
