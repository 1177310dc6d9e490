#pragma once
// A sparse Cholesky factor of K with a set of DOFs taken out (private to the engine). The factor
// itself is a CholeskyFactor (cholesky_factor.h): CHOLMOD's or the GPL-free one, chosen when
// softshell is configured; everything here and above is the same for both.
//
// DOFs are split three ways: `fixed` (prescribed, eliminated), `pinned` (kept out of the factor
// so that what remains is positive definite even when the fixed DOFs leave rigid-body motions
// free; they are solved for in the small dense system together with the Lagrange multipliers),
// and `factored` (everything else, in the factor).

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "cholesky_factor.h"
#include "softshell/engine/shell_model.h"
#include "softshell/executor.h"
#include "softshell/result.h"

namespace softshell::engine::internal {

/// Thrown when K with the chosen DOFs removed is not positive definite (a mechanism the rigid-
/// mode analysis did not catch); the solver then takes the robust path.
class FactorizationFailed : public Exception {
 public:
  using Exception::Exception;
};

class Factorization {
 public:
  /// Factorizes K restricted to the DOFs neither fixed nor pinned. `motions` (3n x pins, zero on
  /// the fixed DOFs): the free zero-energy motions the pins carry (see pin_block()). Throws
  /// FactorizationFailed if that matrix is not positive definite.
  /// Its sweeps run on the model's executor (two threads on a large factor; one if the model's
  /// `threads` is 1).
  Factorization(const ShellModel& model, std::vector<int32_t> fixed, std::vector<int32_t> pinned,
                const Eigen::MatrixXd& motions);
  /// The same for another symmetric matrix with K's sparsity pattern (both triangles stored; e.g.
  /// a tangent stiffness). With `same_pattern` (a factor of a matrix with this pattern and the
  /// same fixed and pinned DOFs), its ordering and symbolic analysis are reused: only the numeric
  /// factorization runs (`reused_analysis()`); a factor that does not fit is ignored. `motions` as
  /// above; without them (empty) the pins' block is kept as computed. `executor`: where its sweeps
  /// may use a second thread (none: one thread). `precision`: what its sweeps read; with kSingle
  /// every solve, the pins' block included, is one with the rounded factor (a preconditioner's).
  Factorization(const Eigen::SparseMatrix<double>& k, std::vector<int32_t> fixed, std::vector<int32_t> pinned,
                const Factorization* same_pattern = nullptr, const Eigen::MatrixXd& motions = Eigen::MatrixXd(),
                std::shared_ptr<Executor> executor = nullptr, SweepPrecision precision = SweepPrecision::kDouble);
  ~Factorization();
  Factorization(const Factorization&) = delete;
  Factorization& operator=(const Factorization&) = delete;

  /// A process-unique id (the key of what is cached on top of this factor).
  uint64_t id() const { return id_; }
  const std::vector<int32_t>& fixed() const { return fixed_; }
  const std::vector<int32_t>& pinned() const { return pinned_; }
  const std::vector<int32_t>& factored() const { return factored_; }
  /// Index of a DOF among the factored ones, or -1.
  int32_t position(int32_t dof) const { return position_[static_cast<size_t>(dof)]; }
  /// Index of a DOF among the pinned ones, or -1.
  int32_t pin_position(int32_t dof) const { return pin_position_[static_cast<size_t>(dof)]; }
  size_t bytes() const { return bytes_; }
  double factor_ms() const { return factor_ms_; }
  /// True if its sweeps run on two threads (a large factor, an executor of two threads or more).
  bool two_thread_sweeps() const;
  /// True if its sweeps read L rounded to single precision (SweepPrecision::kSingle, where it applies).
  bool single_precision_sweeps() const;
  /// True if the symbolic analysis was taken from `same_pattern`.
  bool reused_analysis() const { return reused_analysis_; }

  /// The pins' part of every solve, computed once: Y_Q = L^-1 P K_aQ (factored x pins) and their
  /// block of the Schur complement, K_QQ - Y_Q^T Y_Q. When the pins carry exact zero-energy
  /// motions Z (K Z = 0 on every DOF not fixed), that block is exactly zero (K_aa^-1 K_aQ =
  /// -Z_a Z_Q^-1, so it is (K Z)_Q Z_Q^-1), and what the subtraction leaves is cancellation noise
  /// that would swamp the constraint rows next to it. It is set to zero only if K Z is at
  /// round-off (`pin_block_zeroed()`); otherwise it is kept as computed.
  const Eigen::MatrixXd& pin_columns() const { return pin_columns_; }
  const Eigen::MatrixXd& pin_block() const { return pin_block_; }
  bool pin_block_zeroed() const { return pin_block_zeroed_; }
  /// Largest |K Z|_i / (|K| |Z|)_i over the DOFs not fixed (0 without pins).
  double pin_motion_residual() const { return pin_motion_residual_; }

  /// The two halves of a solve with K_aa = P^T L L^T P (rows: factored DOFs; thread-safe):
  /// forward(B) = L^-1 P B and backward(Y) = P^T L^-T Y, so K_aa^-1 B = backward(forward(B)) and
  /// B1^T K_aa^-1 B2 = forward(B1)^T forward(B2). (A forward sweep of several columns costs about what one full
  /// solve of one column does.)
  ///
  /// Right-hand sides that are local (a grab touches a few dozen DOFs) make L^-1 P B sparse: it
  /// is nonzero only on the paths from their rows to the root of the elimination tree. The
  /// forward sweep then visits only those columns (or supernodes; on a fill-reducing ordering of a
  /// surface, a small share of the factor); `fraction_read`, if given, receives the share read.
  Eigen::MatrixXd forward(const Eigen::MatrixXd& rhs, double* fraction_read = nullptr) const;
  Eigen::MatrixXd backward(const Eigen::MatrixXd& y) const;

 private:
  void factorize(const Eigen::SparseMatrix<double>& k, const Factorization* same_pattern, SweepPrecision precision);
  void compute_pin_block(const Eigen::SparseMatrix<double>& k, const Eigen::MatrixXd& motions);

  uint64_t id_ = 0;
  std::vector<int32_t> fixed_, pinned_, factored_, position_, pin_position_;
  Eigen::MatrixXd pin_columns_, pin_block_;
  bool pin_block_zeroed_ = true;
  double pin_motion_residual_ = 0.0;
  std::unique_ptr<const CholeskyFactor> factor_;
  std::shared_ptr<Executor> executor_;  // for the sweeps (null: one thread)
  uint64_t pattern_hash_ = 0;  // of K_aa's upper pattern: a same-pattern factor must match it
  bool reused_analysis_ = false;
  size_t bytes_ = 0;
  double factor_ms_ = 0.0;
};

/// A sparse Cholesky factor of a general sparse symmetric matrix (the zero-mode analysis of the
/// scalar surface Gram matrix). Not a failure when the matrix is not positive definite: `ok()`
/// then says so. Thread-safe once built.
class SparseCholesky {
 public:
  /// `a`: symmetric, both triangles or the upper one stored (only the upper one is read).
  explicit SparseCholesky(const Eigen::SparseMatrix<double>& a);
  ~SparseCholesky();
  SparseCholesky(const SparseCholesky&) = delete;
  SparseCholesky& operator=(const SparseCholesky&) = delete;

  /// True if the factorization reached the end with positive pivots.
  bool ok() const { return factor_ != nullptr; }
  /// The smallest pivot (squared diagonal entry of L); 0 if !ok().
  double min_pivot() const { return min_pivot_; }
  /// A^-1 B (requires ok()).
  Eigen::MatrixXd solve(const Eigen::MatrixXd& b) const;

 private:
  std::unique_ptr<const CholeskyFactor> factor_;
  double min_pivot_ = 0.0;
};

}  // namespace softshell::engine::internal
