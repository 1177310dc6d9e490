#pragma once
/// \file
/// \brief `FactorCache`: CHOLMOD factors of K with a set of DOFs eliminated, shared by all solvers
/// and evicted least-recently-used under a memory budget.

#include <cstddef>
#include <cstdint>
#include <memory>

namespace softshell::engine {

/// Counters of a factor cache.
struct FactorCacheStats {
  size_t bytes = 0;        ///< memory held by cached factors
  size_t budget = 0;       ///< the budget in bytes
  size_t entries = 0;
  uint64_t hits = 0;
  uint64_t misses = 0;
  uint64_t evictions = 0;
};

/// Thread-safe LRU cache of factorizations, keyed by (model, set of eliminated DOFs).
///
/// Several solvers asking for the same missing factor at once share one factorization.
class FactorCache {
 public:
  /// `budget_bytes`: factors are evicted (least recently used first) to stay under it. A factor
  /// larger than the whole budget is used for its solve and not kept.
  explicit FactorCache(size_t budget_bytes = size_t{1} << 30);
  ~FactorCache();
  FactorCache(const FactorCache&) = delete;
  FactorCache& operator=(const FactorCache&) = delete;

  FactorCacheStats stats() const;
  /// Drops every factor of a model (`ShellModel::id()`), e.g. when its geometry is removed.
  void forget_model(uint64_t model_id);
  void clear();

  struct Impl;
  Impl& impl() { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace softshell::engine
