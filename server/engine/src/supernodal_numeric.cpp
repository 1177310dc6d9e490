// The numeric supernodal factorization's entry points (supernodal_numeric.h): A's entries in the
// factor's order, and the choice of the kernel build.
#include "supernodal_numeric.h"

#include <algorithm>

namespace softshell::engine::internal {
namespace {

using Kernel = SupernodalOutcome (*)(const SupernodalLayout&, const int64_t*, const int32_t*, const int32_t*,
                                     const double*, double*);

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
                                    const double* a_values, double* values) {
  return kernel()(layout, entries.start.data(), entries.row.data(), entries.value.data(), a_values, values);
}

const char* supernodal_kernels() {
  return kernel() == &supernodal_kernel::factor_baseline ? "baseline" : "x86-64-v3";
}

}  // namespace softshell::engine::internal
