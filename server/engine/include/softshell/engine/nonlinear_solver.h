#pragma once
/// \file
/// \brief `NonlinearSolver`: equilibrium of the geometrically nonlinear Kirchhoff-Love shell
/// (large displacements and rotations, small strains; PROTOCOL.md "The nonlinear model").

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <vector>

#include <Eigen/Core>

#include "softshell/deformation.h"
#include "softshell/engine/factor_cache.h"
#include "softshell/engine/shell_model.h"
#include "softshell/executor.h"
#include "softshell/result.h"

namespace softshell::engine {

namespace internal {
class NonlinearShell;
struct NonlinearMemory;
}  // namespace internal

/// One load step of a nonlinear solve, as NonlinearOptions::on_load_step sees it when it ends.
/// A request is a homotopy from the solve's start (0) to what it asks (1), taken in one load step
/// when Newton converges from the start, else in several; a load step that does not converge is
/// tried again at half its length from the same start (or the request is refused).
struct NonlinearLoadStep {
  double from = 0.0;      ///< where it started along the request, 0..1
  double to = 0.0;        ///< where it was to end (converged: where the next one starts)
  bool converged = false;
  int32_t iterations = 0;          ///< nonlinear iterations (directions computed)
  int32_t trust_region_steps = 0;  ///< of which trust-region steps
  int32_t krylov_iterations = 0;
  int32_t factorizations = 0;
  /// The relative out-of-balance force each time the iteration measured it, in order (at each
  /// iteration's start; a state measured again on another quadrature rule appears twice). The
  /// last entry is where the load step ended. The first of a drag step that starts from the last
  /// answer is tiny: that state met the last request (the next direction moves the grab).
  std::vector<double> residuals;
  double ms = 0.0;  ///< wall-clock time of the load step
};

/// Limits and tolerances of a nonlinear solve.
struct NonlinearOptions {
  /// Converged when the out-of-balance force (loads minus internal forces, less the constraint
  /// reactions) is below this fraction of the forces acting (loads, internal forces, reactions).
  double tolerance = 1e-8;
  /// Iterations (each one evaluation of the internal forces) over all load steps.
  int max_iterations = 1000;
  /// Load steps: a request the solver cannot bring to equilibrium in one step is approached in
  /// smaller ones, at most this many, none smaller than 1/1024 of the whole.
  int max_load_steps = 64;
  /// Where the internal forces and tangents are computed (the host's threads); empty =
  /// softshell::default_executor().
  std::shared_ptr<Executor> executor;
  /// At most this many of the executor's threads work on one solve (0 = all of them).
  int threads = 0;
  /// Gauss points per direction on each (sub-)face of the coarse rule (0: none, the model's own
  /// rule everywhere). The preconditioner's tangent is integrated with it, and so is the
  /// nonlinear remainder of the tangent the Newton directions solve while Newton on it converges
  /// fast (`approximate_directions`). The answer's residual always uses the model's rule (the
  /// first iterations' may use the early rule, `early_rule_levels`). Range 0..10.
  int tangent_gauss_points = 4;
  /// Newton directions on K plus the coarse rule's nonlinear remainder of the tangent (measured on
  /// catmark_righthanded: a Krylov iteration of about 2 ms instead of 7-23 ms) until an iteration gains
  /// less than a factor of 5 and most of what is left is what the approximation mispredicted of
  /// the last step's change of the internal forces; from then on to the end of that load step,
  /// and with false, on the exact tangent. The answer is the same either way (the same residual and tolerance).
  bool approximate_directions = true;
  /// With `approximate_directions`, in a request taken in several load steps (a large pull from
  /// rest): the intermediate load steps, and the last one's first iterations (until the
  /// out-of-balance force is below 1e-3 of the forces acting), evaluate the forces on the model's
  /// rule with this many refinement levels toward extraordinary vertices
  /// (QuadratureOptions::ev_refinement_levels), where that has a third fewer points or less. Its
  /// forces differ from the model's by 1e-5..1e-4 of the forces acting (catmark_righthanded, 2
  /// levels against 6), far below what those iterations leave, and cost 1.5 ms there instead of
  /// 4.2. A request's only load step (a drag step) does not use it. The answer is the same: it
  /// converges, and is checked, on the model's rule. -1: none. Range -1..8.
  int early_rule_levels = 2;
  /// Decide when to refactor the preconditioner by counting Krylov iterations (a refresh counted
  /// as 20 per factorization it took) rather than timing them. The same requests then take the
  /// same path to the same answer bit for bit however busy the host (the same build, thread count
  /// and instruction set); timed decisions (false) depend on the host's load, other solves running
  /// beside this one included, and can send a drag past a buckling load to another buckled shape
  /// from run to run. Measured (docs/benchmarks.md, seventeenth and eighteenth sessions):
  /// catmark_righthanded takes the same iterations either way; spot_quadrangulated's drag along 12
  /// directions took 6.2 s a step counted against 5.4 s timed, within the host's own noise (the 4
  /// directions measured last: 396 s against 398 s). Only `time_limit_seconds` still reads the
  /// clock.
  bool reproducible = true;
  /// If set and it becomes true, a running solve stops at its next iteration with kCancelled
  /// (a server shutting down; the flag must outlive the solver).
  const std::atomic<bool>* cancel = nullptr;
  /// Wall-clock seconds a solve may take (0 = no limit): one that has not converged by then stops
  /// at its next iteration and is refused like one that reached the iteration limit
  /// (kUnprocessable, with how far it got and what to try). The service sets 60 s.
  double time_limit_seconds = 0.0;
  /// Called on the solving thread after each load step ends, converged or not (a refused
  /// request's too, but for a load step stopped by the time limit or a cancellation): where a
  /// solve spends its iterations, for benchmarks and for diagnosing slow or refused requests
  /// (`bench_drag_paths` prints them with SOFTSHELL_BENCH_LOAD_STEPS=1). Solves running at once
  /// call it at once, each from its own thread; it must not call back into the solver.
  /// Empty: nothing is recorded.
  std::function<void(const NonlinearLoadStep&)> on_load_step;
};

/// What a nonlinear solve did.
struct NonlinearStats {
  int32_t iterations = 0;         ///< nonlinear iterations (directions computed), all load steps
  int32_t approximate_iterations = 0;  ///< of which with directions on the approximate tangent
  /// of which exact directions with tangent products by differences of the internal forces
  /// (after approximate ones, where an exact product would need a second pass over the points)
  int32_t difference_iterations = 0;
  /// of which trust-region steps on the potential energy (where Newton stalled on an indefinite
  /// tangent, or wandered near an unstable state, instead of converging)
  int32_t trust_region_steps = 0;
  int32_t evaluations = 0;        ///< evaluations of the internal forces (iterations + line searches)
  int32_t early_evaluations = 0;  ///< of which on the early rule (NonlinearOptions::early_rule_levels)
  int32_t load_steps = 0;         ///< 1 when the request converged in one step
  int32_t krylov_iterations = 0;  ///< GMRES iterations (each one tangent product and one solve)
  int32_t factorizations = 0;     ///< tangent stiffness factorizations
  /// A drag step's start: a request continuing the last answer of a drag in the same direction
  /// starts from a state extrapolated from the drag's last answers, unless that state leaves
  /// more than half of the forces acting out of balance (as past a buckling load, where the
  /// extrapolated shape is on no branch): then it starts from the last answer, and if it cannot
  /// converge from there, from the prediction after all before it refuses the request.
  enum class Prediction : int8_t { kNone, kUsed, kDiscarded, kUsedAfterAll };
  Prediction prediction = Prediction::kNone;
  double residual = 0.0;          ///< final relative out-of-balance force (< tolerance)
  /// The answer's check (the safety net): the largest residual / allowance over the nonlinear
  /// equilibrium and every constraint row (<= 1; an answer that fails it is refused).
  double check_ratio = 0.0;
  double strain_energy = 0.0;     ///< J
  double solve_ms = 0.0;          ///< total
  double evaluate_ms = 0.0;       ///< of which evaluating internal forces
  double krylov_ms = 0.0;         ///< of which GMRES (tangent products and preconditioner solves)
  double tangent_ms = 0.0;        ///< of which assembling and factorizing tangents
};

/// A nonlinear equilibrium.
struct NonlinearSolution {
  Eigen::VectorXd displacement;  ///< 3n: DOF 3i + a is axis a of control point i
  NonlinearStats stats;
};

/// Solves deformation requests with the nonlinear model: total Lagrangian Kirchhoff-Love shell
/// with exact Green-Lagrange membrane strains and the exact change of curvature of the deformed
/// limit surface, St. Venant-Kirchhoff material with the model's E, nu, t (the linear model is its
/// first-order term). Forces and `surface_load` keep their direction; `pressure` follows the
/// deformed normal. Vertex, Lagrange and limit constraints are linear in the control points, as
/// in the linear model.
///
/// Equilibrium by inexact Newton iterations: each Newton direction solves the exact tangent
/// stiffness by GMRES, preconditioned by the cached linear factor at rest and by a tangent
/// factored at a deformed state once the Krylov iterations slow down; load steps chosen by the
/// solver when one step is too large.
///
/// Errors: those of the linear `Solver` (kInvalidArgument, kUnprocessable for undetermined or
/// contradictory constraints), and kUnprocessable for a request the solver cannot bring to
/// equilibrium within its limits (the message says how far it got and what to try). Never
/// returns NaN or an unconverged displacement.
///
/// Thread-safety: `solve` may be called from many threads at once. The solver remembers the last
/// tangent factor and the curvature information of its last solve, which the next solve starting
/// from that solve's answer (a drag) reuses.
class NonlinearSolver {
 public:
  NonlinearSolver(std::shared_ptr<const ShellModel> model, std::shared_ptr<FactorCache> cache,
                  NonlinearOptions options = {});
  ~NonlinearSolver();
  NonlinearSolver(const NonlinearSolver&) = delete;
  NonlinearSolver& operator=(const NonlinearSolver&) = delete;

  /// From the rest state.
  Result<NonlinearSolution> solve(const DeformationRequest& request) const;
  /// From `initial` (3n), e.g. the previous answer of a drag: much faster when it is close to the
  /// answer. Any displacement is accepted; the answer does not depend on it unless the request
  /// has several equilibria (the solver finds the one reached from `initial`).
  Result<NonlinearSolution> solve(const DeformationRequest& request, const Eigen::VectorXd& initial) const;

  const ShellModel& model() const { return *model_; }
  const NonlinearOptions& options() const { return options_; }

  /// What the solver holds beyond the model: the quadrature basis of the nonlinear model (built
  /// by the first solve; tens of MB for a few thousand DOFs) and what the last solve left for the
  /// next (a tangent factor). For a host's memory budget.
  size_t memory_bytes() const;

 private:
  std::shared_ptr<const internal::NonlinearShell> shell() const;
  Result<NonlinearSolution> solve_from(const DeformationRequest& request, const Eigen::VectorXd* initial) const;

  std::shared_ptr<const ShellModel> model_;
  std::shared_ptr<FactorCache> cache_;
  NonlinearOptions options_;
  mutable std::mutex mutex_;  // guards shell_ and memory_
  mutable std::shared_ptr<const internal::NonlinearShell> shell_;
  mutable std::shared_ptr<const internal::NonlinearMemory> memory_;
};

}  // namespace softshell::engine
