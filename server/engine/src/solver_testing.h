#pragma once
// Test hooks of the solver (private; tests include this header to force bad paths).

#include <atomic>

#include <Eigen/Core>

namespace softshell::engine::internal {

/// When set, called with every fast-path answer (the displacement, 3n) just before the final
/// check: a test corrupts it there and sees the check catch it. Never set outside tests.
using FastPathCorruption = void (*)(Eigen::VectorXd& displacement);
extern std::atomic<FastPathCorruption> g_corrupt_fast_path;

/// The same for every answer of the nonlinear solver, just before its final check.
extern std::atomic<FastPathCorruption> g_corrupt_nonlinear_answer;

/// When set, the nonlinear solver's exact directions take their tangent products as differences
/// of the internal forces from the start of every load step (normally only after approximate
/// directions ran slow), wherever the accuracy asked of GMRES allows them.
extern std::atomic<bool> g_directions_by_difference;

/// When set, called with a drag step's predicted change of the displacements (3n) before the
/// step evaluates it: a test spoils the prediction there and sees the step discard it.
extern std::atomic<FastPathCorruption> g_corrupt_prediction;

/// When positive, that many of the nonlinear solver's next load steps fail at once (counted
/// down), as load steps Newton cannot converge: a test drives the solver down its fallbacks.
extern std::atomic<int> g_fail_load_steps;

/// When set, called as each load step of the nonlinear solver starts, with the fractions of the
/// request it goes from and to; a load step it returns true for fails at once (a test chooses
/// which, and sees what the solver tries next).
using LoadStepFilter = bool (*)(double from, double to);
extern std::atomic<LoadStepFilter> g_fail_load_step;

/// When set, called with every Newton direction of the nonlinear solver (3n) before the step
/// along it, and the relative out-of-balance force it starts from: a test spoils directions there
/// so that Newton stops making progress.
using DirectionSpoiler = void (*)(double residual, Eigen::VectorXd& direction);
extern std::atomic<DirectionSpoiler> g_spoil_newton_direction;

/// When positive, every tangent product of the nonlinear solver's Krylov iterations sleeps that
/// many microseconds first: a test slows the host down and sees the answers stay the same.
extern std::atomic<int> g_tangent_product_delay_us;

}  // namespace softshell::engine::internal
