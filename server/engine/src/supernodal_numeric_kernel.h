#pragma once
// The numeric kernel of supernodal_numeric.h, built twice (supernodal_numeric_kernel.cpp): plain
// types only, so that the copy compiled for x86-64-v3 shares nothing with the rest but this.

#include <cstdint>
#include <limits>

#include "supernodal_layout.h"

namespace softshell::engine::internal {

struct SupernodalOutcome {
  int64_t failed_column = -1;  ///< first factor column whose pivot was not positive (or not finite); -1 if none
  bool not_finite = false;     ///< that pivot was NaN or infinite
  double min_diagonal = std::numeric_limits<double>::infinity();  ///< min L_kk, when it succeeded
};

/// A's entries in the factor's order as plain arrays (FactorOrderEntries) and its values.
struct SupernodalInput {
  const int64_t* start = nullptr;
  const int32_t* row = nullptr;
  const int32_t* value = nullptr;
  const double* a_values = nullptr;
};

/// The bookkeeping of one left-looking factorization, shared by the threads that run parts of it
/// (per supernode; each entry is touched by one thread at a time: the one that factors the
/// supernode's part of the tree, then the one that factors the top).
struct SupernodalLinks {
  int32_t* link = nullptr;       // next in the list the supernode waits in
  int64_t* next_row = nullptr;   // where its rows in the supernode it waits for begin
  int64_t* pushed_at = nullptr;  // the supernode being factored when it was put into that list
};

/// One thread's scratch: its lists' heads (per supernode, -1 = empty; ns of them) and a column
/// map (one entry per column).
struct SupernodalScratch {
  int32_t* head = nullptr;
  int32_t* map = nullptr;
};

/// A second thread for the large dense work of the supernodes factored after the tree's two
/// halves: update products (with their scatter) and triangular solves, split into two bands of
/// rows (plain types: the kernel is built twice). run(context, task, argument) calls
/// task(argument, 0) and task(argument, 1) at once and returns when both are done.
struct SupernodalShare {
  void (*run)(void* context, void (*task)(void* argument, int part), void* argument) = nullptr;
  void* context = nullptr;
  double min_flops = std::numeric_limits<double>::infinity();  // less work stays on one thread
};

namespace supernodal_kernel {

/// Factors the supernodes order[0 .. count) (ascending), each after gathering the updates of its
/// descendants from the lists heads[0 .. lists), lists <= 4 (merged by the time they were put there, the
/// latest first: the order a factorization of the whole tree on one thread gathers them in, so
/// the arithmetic is the same bit for bit); finished supernodes and relinked descendants go into
/// heads[0]. Stops at the first supernode whose diagonal block is not positive definite; the
/// outcome's min_diagonal is over the supernodes factored. Built twice: the baseline build and,
/// where the compiler could build it (SOFTSHELL_X86_64_V3_KERNELS), the x86-64-v3 one. `share`
/// (may be null): the large update products and triangular solves are computed by two threads,
/// with the same bits.
SupernodalOutcome factor_baseline(const SupernodalLayout& layout, const SupernodalInput& a, const int32_t* order,
                                  int64_t count, const SupernodalScratch* heads, int lists, SupernodalLinks links,
                                  double* values, const SupernodalShare* share);
SupernodalOutcome factor_x86_64_v3(const SupernodalLayout& layout, const SupernodalInput& a, const int32_t* order,
                                   int64_t count, const SupernodalScratch* heads, int lists, SupernodalLinks links,
                                   double* values, const SupernodalShare* share);

}  // namespace supernodal_kernel
}  // namespace softshell::engine::internal
