#pragma once
/// \file
/// \brief `Solver`: static solves K u = f with prescribed DOFs and linear constraints, on a cached
/// CHOLMOD factor so that a new grab point costs triangular solves, not a new factorization.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "softshell/deformation.h"
#include "softshell/engine/factor_cache.h"
#include "softshell/engine/shell_model.h"
#include "softshell/result.h"

namespace softshell::engine {

/// Which way a system was solved.
enum class SolvePath : uint8_t {
  kCachedFactor,  ///< Cholesky of K with fixed DOFs eliminated (cached), constraints by Schur complement
  kFallback,      ///< sparse LU of the full KKT system (robust, slower)
};

/// What a solve did (for metrics and tests).
struct SolveStats {
  SolvePath path = SolvePath::kCachedFactor;
  bool factor_cache_hit = false;
  int32_t constraint_rows = 0;  ///< Lagrange / limit / extra rows after dropping duplicates
  double factor_ms = 0.0;       ///< time spent factorizing (0 on a cache hit)
  int32_t refinement_steps = 0; ///< iterative refinement steps taken (each one more solve)
  /// Share of the factor the forward sweep read: below 1 when loads and constraints are local
  /// (a grab, a push), since then only the elimination-tree paths from their DOFs are swept.
  double forward_fraction = 1.0;
  double solve_ms = 0.0;        ///< total time of the solve
};

/// A solved deformation.
struct Solution {
  Eigen::VectorXd displacement;  ///< 3n: DOF 3i + a is axis a of control point i
  SolveStats stats;
  /// Deformed control points: rest positions + displacement.
  std::vector<Vec3> positions(const ControlMesh& mesh) const;
};

/// Solves deformation requests for one model.
///
/// Precondition: the request passes `validate_request` for this model (the service validates
/// every request once at its boundary); one that does not fails the engine's SOFTSHELL_ASSERT
/// (by default an error kInternal naming the bad element).
/// Errors: kUnprocessable for an undetermined system (a rigid-body motion left free; the message
/// names it) or contradictory constraints. Never returns NaN.
///
/// Thread-safety: `solve` may be called from many threads at once.
class Solver {
 public:
  Solver(std::shared_ptr<const ShellModel> model, std::shared_ptr<FactorCache> cache);

  /// The fast path (cached factor + Schur complement), falling back to the robust path when the
  /// fast one cannot take the system.
  Result<Solution> solve(const DeformationRequest& request) const;

  /// Always the robust path (for tests and as a cross-check).
  Result<Solution> solve_with_fallback(const DeformationRequest& request) const;

  const ShellModel& model() const { return *model_; }

 private:
  Solution solve_on_cached_factor(const DeformationRequest& request) const;  // throws Exception

  std::shared_ptr<const ShellModel> model_;
  std::shared_ptr<FactorCache> cache_;
};

}  // namespace softshell::engine
