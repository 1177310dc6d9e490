#pragma once
// FactorCache internals shared with the solver (private).

#include <functional>
#include <future>
#include <map>
#include <mutex>
#include <vector>

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
    bool ready = false;
  };

  /// The factor for (model, fixed), built with `build` if missing (once, even if many threads ask).
  std::shared_ptr<const internal::Factorization> get(
      uint64_t model_id, const std::vector<int32_t>& fixed,
      const std::function<std::shared_ptr<const internal::Factorization>()>& build, bool& hit);

  /// The cached factor of the model with the largest fixed set contained in `fixed` that lacks at
  /// most `max_extra` of its DOFs, or null.
  std::shared_ptr<const internal::Factorization> find_subset(uint64_t model_id, const std::vector<int32_t>& fixed,
                                                             size_t max_extra);

  mutable std::mutex mutex;
  std::map<Key, Slot> slots;
  size_t budget = 0;
  size_t bytes = 0;
  uint64_t clock = 0, hits = 0, misses = 0, evictions = 0;
};

}  // namespace softshell::engine
