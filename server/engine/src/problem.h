#pragma once
// A deformation request turned into linear algebra (private to the engine): prescribed DOFs,
// constraint rows with the prescribed DOFs moved to their right-hand sides, and the load vector;
// the check that they determine the deformation, and the pins of a factorization.

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "constraint_blocks.h"
#include "softshell/deformation.h"
#include "softshell/engine/shell_model.h"

namespace softshell::engine::internal {

/// One scalar linear equation sum coef * u[dof] = rhs, from a Lagrange, limit or vertex constraint.
struct Row {
  Terms terms;         // sorted by DOF, unique, non-zero
  double rhs = 0.0;
  double scale = 0.0;  // magnitude of the equation's terms, for tolerances
  std::string source;  // for messages, e.g. "limit constraint 2 (y)"
  int32_t lagrange = -1, limit = -1;  // the request's constraint it comes from, if any
};

/// A request turned into linear algebra.
struct Problem {
  std::vector<int32_t> fixed;        // sorted DOFs
  Eigen::VectorXd fixed_value;       // 3n, meaningful on fixed DOFs
  std::vector<char> is_fixed;        // 3n
  std::vector<Row> rows;             // with fixed DOFs moved to the right-hand side
  Eigen::VectorXd load;              // 3n
};

/// Validates the request and builds its problem. Throws Exception (kInvalidArgument for a
/// malformed request, kUnprocessable for constraints that cannot hold).
Problem build_problem(const ShellModel& model, const DeformationRequest& request);

/// Throws kUnprocessable if the prescribed DOFs and the rows leave a zero-energy motion free.
/// Free motions that do not move the limit surface (invisible control-mesh modes) are not an
/// error: their amplitude is set to zero by adding a row, unless a load acts on them.
void check_determined(const ShellModel& model, Problem& p);

/// Pins for a factorization with prescribed DOFs `fixed`: one DOF per free zero-energy motion,
/// chosen by pivoted QR so that the rest of K is positive definite, and those motions (3n x
/// pins, zero on the fixed DOFs).
struct Pins {
  std::vector<int32_t> dofs;  // sorted
  Eigen::MatrixXd motions;
};
Pins choose_pins(const ShellModel& model, const std::vector<int32_t>& fixed);

std::string format_number(double x);
std::string axis_name(int a);

/// How far an answer may miss a constraint row, for every solver's final check: kConstraint of
/// the problem's displacement scale (the largest displacement of the answer, prescribed value or
/// constraint target) plus kGeometry of the object's size (coordinates carry ~1e-16 of it, so
/// residuals below that are round-off however small the displacements), both times the row's
/// scale, plus kRoundOff of the sum of the magnitudes of its terms (what evaluating it in double
/// precision can lose).
inline constexpr double kConstraint = 1e-9;
inline constexpr double kGeometry = 1e-13;
inline constexpr double kRoundOff = 1e-12;

struct RowCheck {
  double residual = 0.0;  ///< |row . u - rhs|
  double allowed = 0.0;   ///< what the rule above allows it
};
RowCheck check_row(const Row& row, const Eigen::VectorXd& u, double displacement_scale, double size);

}  // namespace softshell::engine::internal
