#pragma once
// A deformation request turned into linear algebra (private, shared by the linear and the
// nonlinear solver): prescribed DOFs, constraint rows (Lagrange, limit constraints; linear in the
// control points for both models) and the load vector, with the checks that the constraints
// determine the deformation. Defined in solver.cpp.

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Dense>

#include "softshell/deformation.h"
#include "softshell/engine/shell_model.h"

namespace softshell::engine::internal {

/// One scalar linear equation sum coef * u[dof] = rhs, from a Lagrange, limit or vertex constraint.
struct Row {
  std::vector<std::pair<int32_t, double>> terms;  // sorted by DOF, unique
  double rhs = 0.0;
  double scale = 0.0;  // magnitude of the equation's terms, for tolerances
  std::string source;  // for messages, e.g. "limit constraint 2 (y)"
};

/// A request turned into linear algebra: prescribed DOFs, constraint rows and the load vector.
struct Problem {
  std::vector<int32_t> fixed;        // sorted DOFs
  Eigen::VectorXd fixed_value;       // 3n, meaningful on fixed DOFs
  std::vector<char> is_fixed;        // 3n
  std::vector<Row> rows;             // with fixed DOFs moved to the right-hand side
  Eigen::VectorXd load;              // 3n (model.load_vector of the request)
};

/// Validates the request (kInvalidArgument) and builds its problem; contradictory prescriptions
/// are kUnprocessable.
Problem build_problem(const ShellModel& model, const DeformationRequest& request);

/// Throws kUnprocessable if the prescribed DOFs and the rows leave a zero-energy motion free (the
/// message names it); gauges invisible control-mesh modes with extra rows.
void check_determined(const ShellModel& model, Problem& p);

/// Pins for a factorization with prescribed DOFs `fixed`: one DOF per free rigid motion, chosen
/// so that the rest of K is positive definite.
std::vector<int32_t> choose_pins(const ShellModel& model, const std::vector<int32_t>& fixed);

/// Checks that `u` meets every row and is finite; kUnprocessable otherwise.
void check_solution(const Problem& p, const Eigen::VectorXd& u, double length);

/// The small dense symmetric system of the Schur complement, decomposed once and solved for
/// several right-hand sides (iterative refinement): symmetric diagonal scaling, then a complete
/// orthogonal decomposition (minimum-norm solution when redundant constraints make it singular).
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

}  // namespace softshell::engine::internal
