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

}  // namespace softshell::engine::internal
