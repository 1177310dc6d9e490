#pragma once
// Constrained solves on a cached factor (private): the linear system
//   [A C^T] [z ]   [r]
//   [C  0 ] [mu] = [g]
// restricted to the DOFs a problem does not prescribe, with A a symmetric matrix of K's pattern
// (K itself, or a tangent stiffness) factored with a subset of those DOFs eliminated. Pinned DOFs
// and the rows C are handled by a Schur complement, as in the linear solver; prescribed DOFs the
// factor does not eliminate become unit rows. Used by the nonlinear solver as its Newton step and
// as the preconditioner of its quasi-Newton iterations.

#include <cmath>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <Eigen/Dense>

#include "factorization.h"
#include "problem.h"

namespace softshell::engine::internal {

/// The small dense symmetric system of the Schur complement, decomposed once and solved for
/// several right-hand sides: symmetric diagonal scaling, then a complete orthogonal decomposition
/// (minimum-norm solution when redundant constraints make it singular).
class SmallSystem {
 public:
  SmallSystem() = default;
  explicit SmallSystem(const Eigen::MatrixXd& s) : scale_(s.rows()) {
    for (Eigen::Index i = 0; i < s.rows(); ++i) {
      const double diag = std::abs(s(i, i));
      const double mag = diag > 0.0 ? diag : s.row(i).cwiseAbs().maxCoeff();
      scale_[i] = mag > 0.0 ? 1.0 / std::sqrt(mag) : 1.0;
    }
    if (s.rows() == 0) return;
    cod_.setThreshold(1e-11);
    cod_.compute(scale_.asDiagonal() * s * scale_.asDiagonal());
  }
  Eigen::VectorXd solve(const Eigen::VectorXd& r) const {
    if (r.size() == 0) return Eigen::VectorXd();
    return scale_.asDiagonal() * cod_.solve(scale_.asDiagonal() * r);
  }

 private:
  Eigen::VectorXd scale_;
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod_;
};

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
