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
  /// Rows whose contribution came from a cached constraint block (repeated constraints: almost
  /// free), and rows this solve added to the cache (they cost about what they cost uncached).
  int32_t reused_rows = 0;
  int32_t cached_rows = 0;
  /// True if the fast path's answer failed the final check (see `Solver`) and the robust path
  /// answered instead.
  bool fast_path_rejected = false;
  /// The final check: the largest residual of equilibrium or of a constraint, relative to its
  /// tolerance (at most 1 for every answer returned).
  double check_ratio = 0.0;
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

/// A range of a request's constraints that is known to repeat in later requests.
struct ConstraintGroup {
  size_t first_limit = 0, limit_count = 0;        ///< request.limit_constraints[first, first + count)
  size_t first_lagrange = 0, lagrange_count = 0;  ///< request.lagrange_constraints[first, first + count)
};

/// Hints for one solve (all optional; an answer never depends on them, only its cost).
struct SolveOptions {
  /// Groups of the request's constraints that will be sent again (a floor, a pinned hold, the
  /// holds that did not change since the last solve): their rows are kept in the factor cache
  /// from this first use on, one cached block per group, extended in the order given (put the
  /// groups that change least first). Without hints the solver keeps by itself the rows that
  /// were also in the previous solve on the same factor, so a repeated set of constraints costs
  /// its full price twice and then almost nothing.
  std::vector<ConstraintGroup> repeated;
};

/// Solves deformation requests for one model.
///
/// Every answer is checked before it is returned: the residual of equilibrium on every DOF that
/// is not prescribed, relative to the forces of the whole problem (loads, reactions, internal
/// forces), and the residual of every constraint, relative to the displacements of the whole
/// problem (the answer's, every prescribed value) and to the precision of the geometry (a
/// displacement 1e-13 of the object's size is round-off). Each is also allowed the round-off of
/// its own terms. A fast-path answer that fails is replaced by the robust path's; if that fails
/// too the request is refused (kUnprocessable) with the residual that failed.
///
/// Constraints that repeat from request to request are cheap: what their rows contribute is
/// cached with the factor (see `SolveOptions::repeated`), so a floor of limit constraints with a
/// new grab costs about one grab.
///
/// Precondition: the request passes `validate_request` for this model (the service validates
/// every request once at its boundary); one that does not fails the engine's SOFTSHELL_ASSERT
/// (by default an error kInternal naming the bad element).
/// Errors: kUnprocessable for an undetermined system (a rigid-body motion left free; the message
/// names it), contradictory constraints, or an answer that fails the check. Never returns NaN.
///
/// Thread-safety: `solve` may be called from many threads at once.
class Solver {
 public:
  Solver(std::shared_ptr<const ShellModel> model, std::shared_ptr<FactorCache> cache);

  /// The fast path (cached factor + Schur complement), falling back to the robust path when the
  /// fast one cannot take the system or its answer fails the check.
  Result<Solution> solve(const DeformationRequest& request, const SolveOptions& options = {}) const;

  /// Always the robust path (for tests and as a cross-check).
  Result<Solution> solve_with_fallback(const DeformationRequest& request) const;

  const ShellModel& model() const { return *model_; }

 private:
  std::shared_ptr<const ShellModel> model_;
  std::shared_ptr<FactorCache> cache_;
  double size_ = 0.0;  // of the geometry, for the final check
};

}  // namespace softshell::engine
