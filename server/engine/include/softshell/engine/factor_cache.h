#pragma once
/// \file
/// \brief `FactorCache`: CHOLMOD factors of K with a set of DOFs eliminated, and what repeated
/// constraint rows contribute on top of them, shared by all solvers and evicted
/// least-recently-used under one memory budget.

#include <cstddef>
#include <cstdint>
#include <memory>

namespace softshell::engine {
namespace internal {
struct FactorCacheAccess;
}  // namespace internal

/// Counters of a factor cache.
struct FactorCacheStats {
  size_t bytes = 0;        ///< memory held: factors, constraint blocks and row histories
  size_t budget = 0;       ///< the budget in bytes
  size_t entries = 0;      ///< cached factors
  uint64_t hits = 0;       ///< factor lookups answered from the cache
  uint64_t misses = 0;
  uint64_t evictions = 0;  ///< factors and constraint blocks evicted (or not kept: larger than the budget)
  size_t constraint_blocks = 0;   ///< cached constraint blocks
  size_t constraint_bytes = 0;    ///< memory held by them (included in `bytes`)
  uint64_t constraint_hits = 0;   ///< solves that reused a cached constraint block
};

/// Thread-safe LRU cache of factorizations, keyed by (model, set of eliminated DOFs), and of
/// constraint blocks: what a set of constraint rows contributes to the solves on one factor (their
/// forward-swept columns and their eliminated block of the Schur complement), keyed by the rows'
/// coefficients. A floor, a pinned edge or an unchanged hold then costs almost nothing in every
/// solve after the first (see `Solver`).
///
/// Several solvers asking for the same missing factor at once share one factorization.
class FactorCache {
 public:
  /// `budget_bytes`: factors and constraint blocks are evicted (least recently used first) to stay
  /// under it. One larger than the whole budget is used for its solve and not kept.
  explicit FactorCache(size_t budget_bytes = size_t{1} << 30);
  ~FactorCache();
  FactorCache(const FactorCache&) = delete;
  FactorCache& operator=(const FactorCache&) = delete;

  FactorCacheStats stats() const;
  /// Drops every factor of a model (`ShellModel::id()`) and what is cached on them, e.g. when its
  /// geometry is removed.
  void forget_model(uint64_t model_id);
  void clear();

  struct Impl;  // server/engine/src/factor_cache_impl.h

 private:
  friend struct internal::FactorCacheAccess;  // the solvers' way in (engine-private)
  std::unique_ptr<Impl> impl_;
};

}  // namespace softshell::engine
