#pragma once
// FactorCache internals shared with the solver (private).

#include <functional>
#include <future>
#include <map>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "constraint_blocks.h"
#include "factorization.h"
#include "softshell/engine/factor_cache.h"

namespace softshell::engine {

struct FactorCache::Impl {
  struct Key {
    uint64_t model_id;
    std::vector<int32_t> fixed;  // sorted
    bool operator<(const Key& o) const { return model_id != o.model_id ? model_id < o.model_id : fixed < o.fixed; }
  };
  struct Slot {
    std::shared_future<std::shared_ptr<const internal::Factorization>> future;
    size_t bytes = 0;
    uint64_t last_use = 0;
    uint64_t factor_id = 0;  // once ready
    bool ready = false;
  };
  struct BlockSlot {
    std::shared_ptr<const internal::ConstraintBlock> block;
    uint64_t last_use = 0;
  };
  // The rows of the last solve on a factor: per row hash, the solve (count) since which the row
  // has been in every solve on it. Rows that were in the previous solve are worth keeping.
  struct History {
    uint64_t solves = 0;
    std::unordered_map<uint64_t, uint64_t> since;
    size_t bytes() const { return sizeof(History) + since.size() * 48; }  // hash node estimate
  };

  /// The factor for (model, fixed), built with `build` if missing (once, even if many threads ask).
  std::shared_ptr<const internal::Factorization> get(
      uint64_t model_id, const std::vector<int32_t>& fixed,
      const std::function<std::shared_ptr<const internal::Factorization>()>& build, bool& hit);

  /// The cached factor of the model with the largest fixed set contained in `fixed` that lacks at
  /// most `max_extra` of its DOFs, or null.
  std::shared_ptr<const internal::Factorization> find_subset(uint64_t model_id, const std::vector<int32_t>& fixed,
                                                             size_t max_extra);

  /// The cached block on the factor with the most rows all of whose row hashes are keys of
  /// `present`, or null. (The caller verifies the rows themselves.)
  std::shared_ptr<const internal::ConstraintBlock> find_block(uint64_t factor_id,
                                                              const std::unordered_map<uint64_t, int32_t>& present);
  /// Keeps a block if it fits the budget (evicting least recently used blocks and factors).
  void insert_block(std::shared_ptr<const internal::ConstraintBlock> block);
  /// Records the rows of a solve on a factor: `since[i]` receives the solve count since which row
  /// i has been in every solve (the current count if it is new); returns the current count.
  uint64_t record_rows(uint64_t factor_id, const std::vector<uint64_t>& hashes, std::vector<uint64_t>& since);

  size_t held() const { return bytes + block_bytes + history_bytes; }
  // Evicts least recently used entries (never `keep_factor` / `keep_block`) until within budget.
  void shrink(const Slot* keep_factor, const BlockSlot* keep_block);
  void erase_factor(std::map<Key, Slot>::iterator it);  // with its blocks and history

  mutable std::mutex mutex;
  std::map<Key, Slot> slots;
  std::map<std::pair<uint64_t, uint64_t>, BlockSlot> blocks;  // (factor id, block key)
  std::map<uint64_t, History> history;                        // per factor id
  size_t budget = 0;
  size_t bytes = 0, block_bytes = 0, history_bytes = 0;
  uint64_t clock = 0, hits = 0, misses = 0, evictions = 0, block_hits = 0;
};

namespace internal {

// How the engine's solvers reach the cache's entries; FactorCache's public interface is only
// budgets and counters.
struct FactorCacheAccess {
  static FactorCache::Impl& impl(FactorCache& cache) { return *cache.impl_; }
};

}  // namespace internal
}  // namespace softshell::engine
