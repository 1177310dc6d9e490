#include "softshell/engine/factor_cache.h"

#include <algorithm>
#include <future>

#include "factor_cache_impl.h"

namespace softshell::engine {

using internal::Factorization;

FactorCache::FactorCache(size_t budget_bytes) : impl_(std::make_unique<Impl>()) { impl_->budget = budget_bytes; }
FactorCache::~FactorCache() = default;

FactorCacheStats FactorCache::stats() const {
  std::lock_guard lock(impl_->mutex);
  FactorCacheStats s;
  s.bytes = impl_->bytes;
  s.budget = impl_->budget;
  s.entries = impl_->slots.size();
  s.hits = impl_->hits;
  s.misses = impl_->misses;
  s.evictions = impl_->evictions;
  return s;
}

void FactorCache::forget_model(uint64_t model_id) {
  std::lock_guard lock(impl_->mutex);
  for (auto it = impl_->slots.begin(); it != impl_->slots.end();) {
    if (it->first.model_id == model_id && it->second.ready) {
      impl_->bytes -= it->second.bytes;
      it = impl_->slots.erase(it);
    } else {
      ++it;
    }
  }
}

void FactorCache::clear() {
  std::lock_guard lock(impl_->mutex);
  for (auto it = impl_->slots.begin(); it != impl_->slots.end();) {
    if (it->second.ready) {
      impl_->bytes -= it->second.bytes;
      it = impl_->slots.erase(it);
    } else {
      ++it;
    }
  }
}

std::shared_ptr<const Factorization> FactorCache::Impl::get(
    uint64_t model_id, const std::vector<int32_t>& fixed,
    const std::function<std::shared_ptr<const Factorization>()>& build, bool& hit) {
  Key key{model_id, fixed};
  std::promise<std::shared_ptr<const Factorization>> promise;
  {
    std::unique_lock lock(mutex);
    auto it = slots.find(key);
    if (it != slots.end()) {
      ++hits;
      hit = true;
      it->second.last_use = ++clock;
      auto future = it->second.future;
      lock.unlock();
      return future.get();  // may wait for another thread's factorization
    }
    ++misses;
    hit = false;
    Slot slot;
    slot.future = promise.get_future().share();
    slot.last_use = ++clock;
    slots.emplace(key, std::move(slot));
  }
  std::shared_ptr<const Factorization> factor;
  try {
    factor = build();
  } catch (...) {
    std::lock_guard lock(mutex);
    slots.erase(key);
    promise.set_exception(std::current_exception());
    throw;
  }
  {
    std::lock_guard lock(mutex);
    auto it = slots.find(key);
    it->second.ready = true;
    it->second.bytes = factor->bytes();
    bytes += factor->bytes();
    // Evict least recently used ready factors (not this one) until within budget.
    while (bytes > budget) {
      auto victim = slots.end();
      for (auto s = slots.begin(); s != slots.end(); ++s) {
        if (s->second.ready && s != it && (victim == slots.end() || s->second.last_use < victim->second.last_use)) {
          victim = s;
        }
      }
      if (victim == slots.end()) break;
      bytes -= victim->second.bytes;
      slots.erase(victim);
      ++evictions;
    }
    if (bytes > budget) {  // larger than the whole budget: used for this solve only
      bytes -= it->second.bytes;
      slots.erase(it);
      ++evictions;
    }
  }
  promise.set_value(factor);
  return factor;
}

std::shared_ptr<const Factorization> FactorCache::Impl::find_subset(uint64_t model_id,
                                                                   const std::vector<int32_t>& fixed,
                                                                   size_t max_extra) {
  std::lock_guard lock(mutex);
  auto best = slots.end();
  for (auto it = slots.lower_bound(Key{model_id, {}}); it != slots.end() && it->first.model_id == model_id; ++it) {
    const auto& have = it->first.fixed;
    if (!it->second.ready || have.size() > fixed.size() || fixed.size() - have.size() > max_extra) continue;
    if (!std::includes(fixed.begin(), fixed.end(), have.begin(), have.end())) continue;
    if (best == slots.end() || have.size() > best->first.fixed.size()) best = it;
  }
  if (best == slots.end()) return nullptr;
  ++hits;
  best->second.last_use = ++clock;
  return best->second.future.get();
}

}  // namespace softshell::engine
