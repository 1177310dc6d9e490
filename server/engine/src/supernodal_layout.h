#pragma once
// How both CholeskyFactor backends store a supernodal factor L (P A P^T = L L^T): CHOLMOD's
// layout (private to the engine; no Eigen, so that kernels compiled for another instruction set
// can share it: supernodal_numeric.h).

#include <cstdint>

namespace softshell::engine::internal {

/// A supernodal factor as both backends store it (views; the owner keeps the arrays alive).
/// Supernode s holds columns first[s] .. first[s + 1] - 1; its rows (its own columns first, then
/// the rows below, ascending) are rows[row_start[s] .. row_start[s + 1]); its values are a
/// column-major block (rows x columns) at values + value_start[s].
struct SupernodalLayout {
  int64_t supernodes = 0;
  const int32_t* first = nullptr;
  const int64_t* row_start = nullptr;
  const int64_t* value_start = nullptr;
  const int32_t* rows = nullptr;
  const int32_t* supernode_of = nullptr;  // per column
  const double* values = nullptr;
  /// If set, L rounded to single precision at the same offsets as `values`: the sweeps read this
  /// instead (half the bytes; a preconditioner's factor, cholesky_factor.h) and compute in double.
  const float* single = nullptr;

  int64_t columns() const { return supernodes > 0 ? first[supernodes] : 0; }
  int64_t entries() const { return supernodes > 0 ? value_start[supernodes] : 0; }
};

}  // namespace softshell::engine::internal
