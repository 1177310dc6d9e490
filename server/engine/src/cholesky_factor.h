#pragma once
// The sparse Cholesky factor behind Factorization and SparseCholesky (private to the engine):
// P A P^T = L L^T of a symmetric positive definite matrix, with the two triangular halves of a
// solve. Two implementations, chosen when softshell is configured (SOFTSHELL_SPARSE_CHOLESKY):
//   cholmod  cholesky_cholmod.cpp: CHOLMOD's supernodal factor (BLAS). Debian's libcholmod3
//            holds CHOLMOD's GPL modules (Supernodal, Modify, MatrixOps), so a binary linking it
//            carries GPL code.
//   eigen    cholesky_eigen.cpp: a supernodal left-looking L L^T on Eigen's AMD ordering, written
//            here (MPL-2.0 Eigen headers only; no BLAS, no SuiteSparse library).
// Both are thread-safe once built: any number of threads may call forward/backward at once.

#include <atomic>
#include <cstddef>
#include <memory>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "softshell/executor.h"

namespace softshell::engine::internal {

/// CHOLMOD build: factors of at least this many bytes of values that are let go of are kept (at
/// most two) and refactored into by the next factorization of their analysis (8 MB; tests lower
/// it). The Eigen build ignores it.
extern std::atomic<size_t> g_spare_factor_bytes;

/// What a factor's sweeps read.
enum class SweepPrecision {
  kDouble,  ///< L as factored: solves with A to round-off.
  /// A copy of L rounded to single precision, where the factor is supernodal and its scale fits
  /// (else as kDouble): every forward and backward sweep, of any number of columns, is then one
  /// with that L~, so solves are exact for A~ = L~ L~^T, within 2^-23 |L| |L^T| of A (entry by
  /// entry, to first order), and read half the bytes. For preconditioners: a sweep of a large
  /// factor runs at the speed of memory.
  kSingle,
};

class CholeskyFactor {
 public:
  /// Why factorize() returned no factor.
  struct Failure {
    Eigen::Index column = -1;   ///< first column (in A's numbering) whose pivot was not positive; -1 if unknown
    bool not_finite = false;    ///< that pivot was NaN or infinite (A holds non-finite values)
    bool out_of_memory = false;
  };

  /// Factorizes the symmetric matrix A whose upper triangle `upper` holds (compressed CSC; entries
  /// below the diagonal are ignored). With `same_pattern` (a factor of a matrix with exactly this
  /// upper pattern; the caller guarantees it), its ordering and symbolic analysis are reused and
  /// only the numeric factorization runs. Returns null, and says why in `failure`, if A is not
  /// positive definite, holds NaN or infinite values (never a factor with NaNs), or memory ran out.
  /// With an executor of two threads or more, a large factor is filled on two of them (the
  /// same values bit for bit as on one: supernodal_numeric.h). `precision`: what its sweeps read.
  static std::unique_ptr<CholeskyFactor> factorize(const Eigen::SparseMatrix<double>& upper,
                                                   const CholeskyFactor* same_pattern, Failure& failure,
                                                   Executor* executor = nullptr,
                                                   SweepPrecision precision = SweepPrecision::kDouble);
  ~CholeskyFactor();
  CholeskyFactor(const CholeskyFactor&) = delete;
  CholeskyFactor& operator=(const CholeskyFactor&) = delete;

  Eigen::Index size() const;
  /// L^-1 P B. Right-hand sides that are local make the result sparse: it is nonzero only on the
  /// elimination-tree paths from their rows to the root, and only that part of L is read (unless
  /// it is most of L); `fraction_read`, if given, receives the share of L read. With an executor
  /// of two threads or more, a sweep over most of a large factor runs on two of them
  /// (supernodal_sweeps.h).
  Eigen::MatrixXd forward(const Eigen::MatrixXd& rhs, double* fraction_read = nullptr, Executor* executor = nullptr) const;
  /// P^T L^-T Y (on two threads as above).
  Eigen::MatrixXd backward(const Eigen::MatrixXd& y, Executor* executor = nullptr) const;
  /// True if sweeps with an executor run on two threads (a large supernodal factor whose tree
  /// splits well).
  bool two_thread_sweeps() const;
  /// True if its sweeps read a single-precision copy of L (SweepPrecision::kSingle, where it applies).
  bool single_precision_sweeps() const;
  /// The smallest pivot, min_k L_kk^2.
  double min_pivot() const;
  /// Memory held by the factor (bytes), its symbolic part included.
  size_t bytes() const;
  /// Which implementation this build has, e.g. "CHOLMOD supernodal" (for benchmarks and reports).
  static const char* backend();

 private:
  struct State;
  explicit CholeskyFactor(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

}  // namespace softshell::engine::internal
