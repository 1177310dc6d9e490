#pragma once
// The numeric supernodal Cholesky factorization both CholeskyFactor backends run (private to the
// engine): given a factor's supernodal layout (its ordering and supernodes, from either backend's
// analysis) and A in the factor's order, the values of L. A left-looking L L^T: each supernode
// gathers the updates of its descendants, then factors its diagonal block and solves for the
// rows below it, on dense blocks (Ng & Peyton 1993; Davis's CHOLMOD). The code is ours.
//
// Why ours in the CHOLMOD build too: CHOLMOD's numeric factorization calls BLAS once per
// supernode pair and runs OpenMP regions; on small factors that overhead is most of its time. The
// nonlinear model refactors its preconditioner at every drag step: catmark_righthanded's tangent
// (1,245 DOFs) took 9-12 ms in CHOLMOD, 3.6 ms here. On large factors this is as fast or faster
// (first linear solves, interleaved: spot_quadrangulated 215-233 -> 161-169 ms,
// blub_quadrangulated 767-916 -> 622-698 ms; docs/benchmarks.md). CHOLMOD still chooses the
// ordering (METIS for large matrices) and the supernodes; its factor is filled here (a simplicial
// one, which CHOLMOD picks for very sparse factors, by CHOLMOD).
//
// On two threads (a factor whose sweeps are split, supernodal_sweeps.h) both halves of the
// elimination tree are factored at once, then the top. A top supernode gathers its descendants'
// updates in the order one thread over the whole tree would (its lists merged by when each
// descendant was put in them), so the factor is the same bit for bit. The top holds most of the
// flops: spot_quadrangulated's refactorization 77 -> 68 ms, blub_quadrangulated's 320 -> 262 ms.
//
// The dense kernels are Eigen's, compiled twice (supernodal_numeric_kernel.cpp): for the
// baseline and for x86-64-v3 (AVX2, FMA), picked when the library loads, as the nonlinear
// model's point kernels are.

#include <atomic>
#include <cstdint>
#include <vector>

#include <Eigen/SparseCore>

#include "softshell/executor.h"
#include "supernodal_numeric_kernel.h"
#include "supernodal_sweeps.h"

namespace softshell::engine::internal {

/// A's lower triangle in the factor's order (P A P^T), by columns: column k's entries are
/// q in [start[k], start[k + 1]), at row row[q] >= k, with the value values[value[q]] (an index
/// into the matrix's own value array, so one map serves every matrix of the pattern).
struct FactorOrderEntries {
  std::vector<int64_t> start;
  std::vector<int32_t> row;
  std::vector<int32_t> value;
};

/// The entries of the symmetric matrix given by its upper triangle `upper` (compressed CSC) for
/// the ordering `position` (position[i]: where row i of A is in the factor).
FactorOrderEntries factor_order_entries(const Eigen::SparseMatrix<double>& upper, const std::vector<int32_t>& position);

/// Fills `values` (layout.entries() of them, overwritten) with L of A = the matrix whose value
/// array is `a_values`, entered by `entries`. Stops at the first supernode whose diagonal block
/// has a pivot that is not positive or finite (the values are then incomplete). Throws
/// std::bad_alloc if its workspace cannot be had.
/// With `split` and an executor of two threads or more, the two halves of the elimination tree
/// are factored at once and then the top (on_two_threads, as the sweeps), the top's large update
/// products and triangular solves on two threads too: the same values bit for bit, and the same
/// outcome, as on one thread.
SupernodalOutcome factor_supernodes(const SupernodalLayout& layout, const FactorOrderEntries& entries,
                                    const double* a_values, double* values, const TwoThreadSweeps* split = nullptr,
                                    Executor* executor = nullptr);

/// The instruction set the kernels run with here ("x86-64-v3" or "baseline").
const char* supernodal_kernels();

/// Tests and benchmarks: the baseline kernels even where the x86-64-v3 ones can run.
extern std::atomic<bool> g_supernodal_baseline_kernels;
/// Tests and benchmarks: false factors on one thread even where a split and an executor are given.
extern std::atomic<bool> g_two_thread_factorization;
/// Tests and benchmarks: the top's update products and triangular solves of this many flops or
/// more are computed by two threads (infinity: none); and how many have been so far.
extern std::atomic<double> g_shared_product_flops;
extern std::atomic<int64_t> g_shared_products;

}  // namespace softshell::engine::internal
