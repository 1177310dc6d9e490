#pragma once
// What constraint rows contribute to the fast path's small system on one factor, kept for rows
// that repeat from solve to solve (private to the engine).
//
// The fast path solves [K, C^T; C, 0] [u; lambda] = [f; d] on a factor K_aa = P^T L L^T P of K
// without its fixed and pinned DOFs: the small unknowns y = (u_Q, lambda) couple to the factored
// DOFs through H = [K_aQ | C_a^T], and with Y = L^-1 P H the small system is S y = r with
// S = M - Y^T Y. A row contributes a column of Y and entries of S that depend on its
// coefficients only, not on its right-hand side. A ConstraintBlock keeps them for a set of rows
// (a floor, a pinned edge, an unchanged hold), together with the Cholesky factor of
// N = C_B K_aa^-1 C_B^T (= -S_BB) over them: the rows are eliminated once, and a later solve with
// the same rows and a few new ones pays for the new ones only.

#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/QR>

#include "factorization.h"
#include "hash_mix.h"

namespace softshell::engine::internal {

/// The coefficients of one linear equation: (DOF, coefficient), sorted by DOF, unique.
using Terms = std::vector<std::pair<int32_t, double>>;

/// A 64-bit hash of a row's coefficients (the DOFs and the bits of the values).
uint64_t hash_terms(const Terms& terms);
/// Columns of Y, stored on the factor rows where any of them is non-zero (the forward sweep of a
/// local right-hand side reaches only the elimination-tree paths from its DOFs).
struct SweptColumns {
  using Values = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  std::vector<int32_t> rows;  // factor rows, ascending
  Values values;              // rows.size() x columns (row-major: products with local vectors read their rows only)

  static SweptColumns compress(const Eigen::MatrixXd& y);
  /// values^T x(rows, :) for x on all factor rows; with `nonzero` (per factor row), only the rows
  /// where x is non-zero are read.
  Eigen::MatrixXd transpose_times(const Eigen::MatrixXd& x, const std::vector<char>* nonzero = nullptr) const;
  /// out(rows) += values c.
  void add_times(const Eigen::Ref<const Eigen::VectorXd>& c, Eigen::VectorXd& out) const;
  size_t bytes() const;
};

/// The contribution of a set of rows on one factor. Rows are added group by group (a block with
/// one more group extends its parent's factor); within the block they are eliminated in order:
/// `kept` rows by the Cholesky factor L of N, the others (`deferred`: dependent on earlier rows to
/// round-off, or held only through the pins) stay in the small system with the pins: the "core"
/// unknowns are the pins followed by the deferred rows. Immutable, shared between solves.
struct ConstraintBlock {
  uint64_t factor_id = 0;
  uint64_t key = 0;                    // hash of the group keys in order (0: the empty block)
  std::vector<uint64_t> group_keys;
  std::vector<Terms> terms;            // per block row
  std::vector<uint64_t> hashes;        // per block row
  std::vector<std::shared_ptr<const SweptColumns>> groups;  // Y columns of each group's rows
  std::vector<int32_t> group_first;    // first block row of each group
  std::vector<int32_t> kept;           // block rows, in L's order
  std::vector<int32_t> deferred;       // block rows, core positions nq, nq + 1, ...
  Eigen::MatrixXd l;                   // kept x kept, lower triangular
  Eigen::MatrixXd s_kc;                // S(kept, core)
  Eigen::MatrixXd a_cc;                // S(core, core)
  Eigen::MatrixXd w;                   // L^-1 S(kept, core)
  Eigen::MatrixXd t;                   // a_cc + w^T w: the core's system with the kept rows eliminated
  size_t bytes = 0;

  Eigen::Index rows() const { return static_cast<Eigen::Index>(terms.size()); }
  /// Y_B^T x (block rows x columns of x) for x on the factor rows (see SweptColumns).
  Eigen::MatrixXd transpose_times(const Eigen::MatrixXd& x, const std::vector<char>* nonzero = nullptr) const;
  /// out += Y_B c, c per block row.
  void add_times(const Eigen::VectorXd& c, Eigen::VectorXd& out) const;
};

/// The block without rows on a factor: its core is the pins.
std::shared_ptr<const ConstraintBlock> empty_block(const Factorization& factor);

/// `parent` with one more group: `rows` (with their hashes, in the order they are to be kept).
/// Costs one forward sweep of the new rows and products with the parent's columns.
std::shared_ptr<const ConstraintBlock> extend_block(const Factorization& factor, const ConstraintBlock& parent,
                                                   std::vector<Terms> rows, std::vector<uint64_t> hashes,
                                                   uint64_t group_key);

/// The small system of one solve: a block B and the request's other rows G ("new"). Unknowns in
/// the order [pins | block rows | new rows].
class SchurSystem {
 public:
  /// `new_columns`: Y_G (factor rows x new rows), from the solve's own forward sweep.
  SchurSystem(const Factorization& factor, std::shared_ptr<const ConstraintBlock> block, const std::vector<Terms>& new_rows,
              Eigen::MatrixXd new_columns);

  Eigen::Index size() const { return nq_ + block_->rows() + ng_; }
  /// y = S^-1 r (least squares, minimum norm, where redundant rows make S singular).
  Eigen::VectorXd solve(const Eigen::VectorXd& r) const;
  /// Y_H^T z for z on the factor rows.
  Eigen::VectorXd transpose_times(const Eigen::VectorXd& z) const;
  /// Y_H y on the factor rows.
  Eigen::VectorXd times(const Eigen::VectorXd& y) const;

 private:
  const Factorization& factor_;
  std::shared_ptr<const ConstraintBlock> block_;
  Eigen::Index nq_ = 0, ng_ = 0;
  Eigen::MatrixXd y_new_;   // Y_G
  Eigen::MatrixXd w_new_;   // L^-1 S(kept, G)
  // The reduced system over [core | G], symmetrically scaled and decomposed (complete
  // orthogonal decomposition: minimum-norm solutions where redundant rows make it singular).
  Eigen::VectorXd scale_;
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> reduced_;
};

}  // namespace softshell::engine::internal
