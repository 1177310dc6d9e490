#pragma once
// The triangular sweeps of a supernodal Cholesky factor L (P A P^T = L L^T) on two threads
// (private to the engine; both CholeskyFactor backends store their factors this way).
//
// A sweep with one right-hand side reads all of L once and does two flops per entry read: on a
// large factor it runs at the speed of memory, and one core does not draw all of it. The
// elimination tree lets two threads share a sweep: below its top separators it falls apart into
// subtrees that touch disjoint columns. The plan splits the tree into two sets of whole subtrees
// and the supernodes above them (the top, swept by one thread), choosing the split for the least
// top plus larger set:
//   forward (L^-1):  both sets at once, each in ascending order; what they subtract from the
//                    top's rows is gathered per thread and added after; then the top.
//   backward (L^-T): the top first, then both sets at once in descending order (they only read
//                    the top's rows, which are final by then).
// Every supernode does the same arithmetic as in a sweep on one thread; only the order in which
// the two sets' updates reach the top's rows differs (round-off). The answer does not depend on
// which thread sweeps which set, or when: the same bits every time.

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "softshell/executor.h"
#include "supernodal_layout.h"

namespace softshell::engine::internal {

/// Factors with fewer stored entries are swept on one thread (1M entries, 8 MB: about 1 ms a sweep
/// here, where a second thread's wake-up and the top's gathering start to pay), and so are
/// forward sweeps from local right-hand sides that reach fewer than a quarter of that. Tests
/// lower it.
extern std::atomic<int64_t> g_two_thread_sweep_entries;

/// Marks in `reached` (one flag per supernode, the supernodes of the nonzero rows set) every
/// supernode a forward sweep from them reaches, in ascending order, and returns the entries of L
/// they hold; stops early, returning more than `limit`, once they hold more than `limit`.
int64_t reach(const SupernodalLayout& l, std::vector<char>& reached, int64_t limit);

class TwoThreadSweeps;

/// How a forward sweep from some right-hand sides runs (both backends' rule). `reached` (one flag
/// per supernode, those of the nonzero rows set) gets every supernode the sweep reaches.
struct ForwardSweep {
  int64_t work = 0;          ///< entries of L the reached supernodes hold
  bool whole = false;        ///< more than half the factor: sweep all of it (no skipping pays)
  bool two_threads = false;  ///< on two threads: a plan, an executor of two, and a quarter of
                             ///< g_two_thread_sweep_entries reached or more
};
ForwardSweep plan_forward(const SupernodalLayout& l, const TwoThreadSweeps* sweeps, const Executor* executor,
                          std::vector<char>& reached);

class TwoThreadSweeps {
 public:
  /// The plan for `l`'s tree; null if the factor is below g_two_thread_sweep_entries or no split
  /// of its tree (a top of at most half the factor) would make a sweep 10% faster.
  static std::unique_ptr<const TwoThreadSweeps> plan(const SupernodalLayout& l);

  /// x (n x k, rows in factor order) := L^-1 x, on at most two of the executor's threads (the
  /// calling one included). `reached`, if given: the supernodes the sweep reaches from x's nonzero
  /// rows (reach()); the others are skipped.
  template <class X>
  void forward(const SupernodalLayout& l, X& x, Executor& executor, const std::vector<char>* reached = nullptr) const;
  /// x := L^-T x.
  template <class X>
  void backward(const SupernodalLayout& l, X& x, Executor& executor) const;

  /// The split: the supernodes of half 0 or 1 and of the top, ascending (the numeric
  /// factorization on two threads uses it too, supernodal_numeric.h).
  const std::vector<int32_t>& half(int h) const { return halves_[static_cast<size_t>(h)]; }
  const std::vector<int32_t>& top() const { return top_; }
  /// The share of the factor's entries in the top (what one thread sweeps alone).
  double top_share() const { return top_share_; }
  /// Memory held by the plan.
  size_t bytes() const {
    return sizeof(*this) + (halves_[0].size() + halves_[1].size() + top_.size() + top_rows_.size() + top_index_.size()) *
                               sizeof(int32_t);
  }

 private:
  TwoThreadSweeps() = default;
  std::array<std::vector<int32_t>, 2> halves_;  // supernodes, ascending
  std::vector<int32_t> top_;                    // supernodes, ascending
  std::vector<int32_t> top_rows_;               // the top's columns, ascending
  std::vector<int32_t> top_index_;              // per column: its index in top_rows_, or -1
  double top_share_ = 0.0;
};

/// Whether sweeps with `plan` on `executor` run on two threads (both backends' rule).
inline bool on_two_threads(const TwoThreadSweeps* plan, const Executor* executor) {
  return plan && executor && executor->concurrency() > 1;
}

/// L's values rounded to single precision (for SupernodalLayout::single), converted on two of the
/// executor's threads if it has them and the factor is large. Null where they would leave float's
/// range: every |L_ij| is at most sqrt(A_ii) (`upper`: A's upper triangle, diagonal included), and
/// every pivot L_kk (the smallest: `min_diagonal`, the factorization's) must stay a normal float.
std::unique_ptr<float[]> single_copy(const SupernodalLayout& l, const Eigen::SparseMatrix<double>& upper,
                                     double min_diagonal, Executor* executor);

/// One supernode's step of a sweep on one thread (the backends' own sweeps and the plan's share
/// them, so the arithmetic is the same).
template <class X>
void forward_step(const SupernodalLayout& l, int64_t s, X& x);
template <class X>
void backward_step(const SupernodalLayout& l, int64_t s, X& x);

/// The backends' sweeps on one thread: x := L^-1 x over the supernodes flagged in `reached` (all
/// that the sweep reaches: reach()), and x := L^-T x.
template <class X>
void forward_sweep(const SupernodalLayout& l, X& x, const std::vector<char>& reached);
template <class X>
void backward_sweep(const SupernodalLayout& l, X& x);

}  // namespace softshell::engine::internal
