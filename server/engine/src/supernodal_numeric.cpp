// The numeric supernodal factorization's entry points (supernodal_numeric.h): A's entries in the
// factor's order, and the choice of the kernel build.
#include "supernodal_numeric.h"

#include <algorithm>
#include <array>

namespace softshell::engine::internal {
namespace {

using Kernel = SupernodalOutcome (*)(const SupernodalLayout&, const SupernodalInput&, const int32_t*, int64_t,
                                     const SupernodalScratch*, int, SupernodalLinks, double*, const SupernodalShare*);

// Picked once, when the library loads.
Kernel choose_kernel() {
#if defined(SOFTSHELL_X86_64_V3_KERNELS)
  __builtin_cpu_init();
  if (__builtin_cpu_supports("x86-64-v3")) return &supernodal_kernel::factor_x86_64_v3;
#endif
  return &supernodal_kernel::factor_baseline;
}

const Kernel g_kernel = choose_kernel();

// The kernels to run: the x86-64-v3 ones where the CPU has it, unless g_supernodal_baseline_kernels.
Kernel kernel() {
  return g_supernodal_baseline_kernels.load(std::memory_order_relaxed) ? &supernodal_kernel::factor_baseline : g_kernel;
}

}  // namespace

std::atomic<bool> g_supernodal_baseline_kernels{false};
std::atomic<bool> g_two_thread_factorization{true};
// About 0.1 ms of work on one thread: below it, waking the second costs more than it saves.
std::atomic<double> g_shared_product_flops{2e6};
std::atomic<int64_t> g_shared_products{0};

FactorOrderEntries factor_order_entries(const Eigen::SparseMatrix<double>& upper, const std::vector<int32_t>& position) {
  const auto n = static_cast<size_t>(upper.rows());
  FactorOrderEntries a;
  a.start.assign(n + 1, 0);
  for (Eigen::Index j = 0; j < upper.cols(); ++j) {
    for (int p = upper.outerIndexPtr()[j]; p < upper.outerIndexPtr()[j + 1]; ++p) {
      if (upper.innerIndexPtr()[p] > j) continue;
      const int32_t pi = position[static_cast<size_t>(upper.innerIndexPtr()[p])], pj = position[static_cast<size_t>(j)];
      ++a.start[static_cast<size_t>(std::min(pi, pj)) + 1];
    }
  }
  for (size_t k = 0; k < n; ++k) a.start[k + 1] += a.start[k];
  a.row.resize(static_cast<size_t>(a.start[n]));
  a.value.resize(static_cast<size_t>(a.start[n]));
  std::vector<int64_t> next(a.start.begin(), a.start.end() - 1);
  for (Eigen::Index j = 0; j < upper.cols(); ++j) {
    for (int p = upper.outerIndexPtr()[j]; p < upper.outerIndexPtr()[j + 1]; ++p) {
      if (upper.innerIndexPtr()[p] > j) continue;
      const int32_t pi = position[static_cast<size_t>(upper.innerIndexPtr()[p])], pj = position[static_cast<size_t>(j)];
      const auto q = static_cast<size_t>(next[static_cast<size_t>(std::min(pi, pj))]++);
      a.row[q] = std::max(pi, pj);
      a.value[q] = p;
    }
  }
  return a;
}

SupernodalOutcome factor_supernodes(const SupernodalLayout& layout, const FactorOrderEntries& entries,
                                    const double* a_values, double* values, const TwoThreadSweeps* split,
                                    Executor* executor) {
  const Kernel factor = kernel();
  const SupernodalInput a{entries.start.data(), entries.row.data(), entries.value.data(), a_values};
  const auto ns = static_cast<size_t>(layout.supernodes);
  const auto columns = static_cast<size_t>(layout.columns());
  std::vector<int32_t> link(ns, -1);
  std::vector<int64_t> next_row(ns, 0), pushed_at(ns, -1);
  const SupernodalLinks links{link.data(), next_row.data(), pushed_at.data()};
  if (!on_two_threads(split, executor) || !g_two_thread_factorization.load(std::memory_order_relaxed)) {
    std::vector<int32_t> order(ns), head(ns, -1), map(columns, 0);
    for (size_t t = 0; t < ns; ++t) order[t] = static_cast<int32_t>(t);
    const SupernodalScratch scratch{head.data(), map.data()};
    return factor(layout, a, order.data(), static_cast<int64_t>(ns), &scratch, 1, links, values, nullptr);
  }
  // Both halves of the tree at once (their supernodes' descendants are their own), then the top,
  // which gathers from its own list and both halves' (supernodal_sweeps.h: the same split).
  std::array<std::vector<int32_t>, 3> head, map;
  std::array<SupernodalScratch, 3> scratch;
  for (size_t h = 0; h < 3; ++h) {
    head[h].assign(ns, -1);
    map[h].assign(columns, 0);
    scratch[h] = {head[h].data(), map[h].data()};
  }
  std::array<SupernodalOutcome, 2> halves;
  executor->parallel_for(0, 2, [&](int64_t h) {
    const std::vector<int32_t>& order = split->half(static_cast<int>(h));
    halves[static_cast<size_t>(h)] = factor(layout, a, order.data(), static_cast<int64_t>(order.size()),
                                            &scratch[static_cast<size_t>(h)], 1, links, values, nullptr);
  }, 2);
  // A failed half stops the factorization at its failing supernode; the top's supernodes before
  // it are factored still, so that the failure reported is the first in the order of the columns,
  // as on one thread.
  int64_t stop = layout.columns();
  const SupernodalOutcome* failed = nullptr;
  for (const SupernodalOutcome& o : halves) {
    if (o.failed_column >= 0 && o.failed_column < stop) {
      stop = o.failed_column;
      failed = &o;
    }
  }
  const std::vector<int32_t>& top = split->top();
  int64_t count = 0;
  while (count < static_cast<int64_t>(top.size()) && layout.first[top[static_cast<size_t>(count)]] < stop) ++count;
  const std::array<SupernodalScratch, 3> lists{scratch[2], scratch[0], scratch[1]};
  // The top, on this thread with the executor's help for its large products and solves.
  SupernodalShare share;
  share.context = executor;
  share.run = [](void* context, void (*task)(void*, int), void* argument) {
    g_shared_products.fetch_add(1, std::memory_order_relaxed);
    static_cast<Executor*>(context)->parallel_for(0, 2, [&](int64_t part) { task(argument, static_cast<int>(part)); }, 2);
  };
  share.min_flops = g_shared_product_flops.load(std::memory_order_relaxed);
  SupernodalOutcome outcome = factor(layout, a, top.data(), count, lists.data(), 3, links, values, &share);
  if (outcome.failed_column < 0 && failed) outcome = *failed;
  if (outcome.failed_column < 0) outcome.min_diagonal = std::min({outcome.min_diagonal, halves[0].min_diagonal, halves[1].min_diagonal});
  return outcome;
}

const char* supernodal_kernels() {
  return kernel() == &supernodal_kernel::factor_baseline ? "baseline" : "x86-64-v3";
}

}  // namespace softshell::engine::internal
