#pragma once
// Constrained solves on a cached factor (private): the linear system
//   [A C^T] [z ]   [r]
//   [C  0 ] [mu] = [g]
// restricted to the DOFs a problem does not prescribe, with A a symmetric matrix of K's pattern
// (K itself, or a tangent stiffness) factored with a subset of those DOFs eliminated. Pinned DOFs
// and the rows C are handled by a Schur complement, as in the linear solver; prescribed DOFs the
// factor does not eliminate become unit rows. Used by the nonlinear solver as its Newton step and
// as the preconditioner of its quasi-Newton iterations.

#include <memory>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "constraint_rows.h"
#include "factorization.h"

namespace softshell::engine::internal {

class KktOperator {
 public:
  /// `factor`: a factorization of `matrix` whose fixed DOFs are a subset of `p.fixed`.
  /// `zero_energy_pins`: the pins carry exact zero-energy motions of `matrix` (true for K: their
  /// Schur complement is then zero, and what the subtraction leaves is noise).
  KktOperator(std::shared_ptr<const Factorization> factor, std::shared_ptr<const Eigen::SparseMatrix<double>> matrix,
              const Problem& p, bool zero_energy_pins);

  /// z (3n, zero on the problem's prescribed DOFs) with A z + C^T mu = r on the other DOFs and
  /// C z = g (one entry per row of the problem).
  Eigen::VectorXd solve(const Eigen::VectorXd& r, const Eigen::VectorXd& g) const;

  const Factorization& factor() const { return *factor_; }
  const std::shared_ptr<const Factorization>& factor_ptr() const { return factor_; }
  const std::shared_ptr<const Eigen::SparseMatrix<double>>& matrix() const { return matrix_; }

 private:
  std::shared_ptr<const Factorization> factor_;
  std::shared_ptr<const Eigen::SparseMatrix<double>> matrix_;
  std::vector<Row> rows_;             // the problem's rows, then unit rows of prescribed DOFs left in the factor
  std::vector<int32_t> pin_index_;    // per DOF: index among the pins or -1
  Eigen::MatrixXd forward_h_;         // L^-1 P [A_aQ | C_a^T]
  SmallSystem small_;
  size_t problem_rows_ = 0;
};

/// The out-of-balance part of a force vector: r minus the constraint reactions C^T mu that best
/// explain it (least squares), on the DOFs a problem does not prescribe (zero on those it does).
class Reactions {
 public:
  explicit Reactions(const Problem& p);
  Eigen::VectorXd out_of_balance(const Eigen::VectorXd& r) const;

 private:
  const Problem& p_;
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> gram_;
};

}  // namespace softshell::engine::internal
