#pragma once
// Test hooks of the solver (private; tests include this header to force bad paths).

#include <atomic>

#include <Eigen/Core>

namespace softshell::engine::internal {

/// When set, called with every fast-path answer (the displacement, 3n) just before the final
/// check: a test corrupts it there and sees the check catch it. Never set outside tests.
using FastPathCorruption = void (*)(Eigen::VectorXd& displacement);
extern std::atomic<FastPathCorruption> g_corrupt_fast_path;

}  // namespace softshell::engine::internal
