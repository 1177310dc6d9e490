#include "softshell/engine/factor_cache.h"

#include <algorithm>
#include <future>

#include "factor_cache_impl.h"

namespace softshell::engine {

using internal::ConstraintBlock;
using internal::Factorization;

namespace {
constexpr size_t kMaxBlocksPerFactor = 32;
}  // namespace

FactorCache::FactorCache(size_t budget_bytes) : impl_(std::make_unique<Impl>()) { impl_->budget = budget_bytes; }
FactorCache::~FactorCache() = default;

FactorCacheStats FactorCache::stats() const {
  std::lock_guard lock(impl_->mutex);
  FactorCacheStats s;
  s.bytes = impl_->held();
  s.budget = impl_->budget;
  s.entries = impl_->slots.size();
  s.hits = impl_->hits;
  s.misses = impl_->misses;
  s.evictions = impl_->evictions;
  s.constraint_blocks = impl_->blocks.size();
  s.constraint_bytes = impl_->block_bytes;
  s.constraint_hits = impl_->block_hits;
  return s;
}

void FactorCache::Impl::erase_factor(std::map<Key, Slot>::iterator it) {
  const uint64_t id = it->second.factor_id;
  bytes -= it->second.bytes;
  slots.erase(it);
  for (auto b = blocks.lower_bound({id, 0}); b != blocks.end() && b->first.first == id;) {
    block_bytes -= b->second.block->bytes;
    b = blocks.erase(b);
  }
  if (auto h = history.find(id); h != history.end()) {
    history_bytes -= h->second.bytes();
    history.erase(h);
  }
}

void FactorCache::forget_model(uint64_t model_id) {
  std::lock_guard lock(impl_->mutex);
  for (auto it = impl_->slots.begin(); it != impl_->slots.end();) {
    if (it->first.model_id == model_id && it->second.ready) {
      impl_->erase_factor(it++);
    } else {
      ++it;
    }
  }
}

void FactorCache::clear() {
  std::lock_guard lock(impl_->mutex);
  for (auto it = impl_->slots.begin(); it != impl_->slots.end();) {
    if (it->second.ready) {
      impl_->erase_factor(it++);
    } else {
      ++it;
    }
  }
}

void FactorCache::Impl::shrink(const Slot* keep_factor, const BlockSlot* keep_block) {
  while (held() > budget) {
    auto factor = slots.end();
    for (auto s = slots.begin(); s != slots.end(); ++s) {
      if (s->second.ready && &s->second != keep_factor &&
          (factor == slots.end() || s->second.last_use < factor->second.last_use)) {
        factor = s;
      }
    }
    auto block = blocks.end();
    for (auto b = blocks.begin(); b != blocks.end(); ++b) {
      if (&b->second != keep_block && (block == blocks.end() || b->second.last_use < block->second.last_use)) block = b;
    }
    const bool take_block =
        block != blocks.end() && (factor == slots.end() || block->second.last_use < factor->second.last_use);
    if (take_block) {
      block_bytes -= block->second.block->bytes;
      blocks.erase(block);
    } else if (factor != slots.end()) {
      erase_factor(factor);
    } else {
      break;
    }
    ++evictions;
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
    it->second.factor_id = factor->id();
    bytes += factor->bytes();
    shrink(&it->second, nullptr);
    if (held() > budget) {  // larger than the whole budget: used for this solve only
      erase_factor(it);
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

std::shared_ptr<const ConstraintBlock> FactorCache::Impl::find_block(
    uint64_t factor_id, const std::unordered_map<uint64_t, int32_t>& present) {
  std::lock_guard lock(mutex);
  auto best = blocks.end();
  for (auto it = blocks.lower_bound({factor_id, 0}); it != blocks.end() && it->first.first == factor_id; ++it) {
    const ConstraintBlock& b = *it->second.block;
    if (best != blocks.end() && b.rows() <= best->second.block->rows()) continue;
    if (static_cast<size_t>(b.rows()) > present.size()) continue;
    if (std::all_of(b.hashes.begin(), b.hashes.end(), [&](uint64_t h) { return present.count(h) > 0; })) best = it;
  }
  if (best == blocks.end()) return nullptr;
  ++block_hits;
  best->second.last_use = ++clock;
  return best->second.block;
}

void FactorCache::Impl::insert_block(std::shared_ptr<const ConstraintBlock> block) {
  std::lock_guard lock(mutex);
  // Only on a factor that is still cached (its id would never be asked for again otherwise).
  const bool live = std::any_of(slots.begin(), slots.end(),
                                [&](const auto& s) { return s.second.ready && s.second.factor_id == block->factor_id; });
  if (!live) return;
  const size_t size = block->bytes;
  auto [it, inserted] = blocks.try_emplace({block->factor_id, block->key});
  if (!inserted) {  // another solve made the same block meanwhile
    it->second.last_use = ++clock;
    return;
  }
  it->second.block = std::move(block);
  it->second.last_use = ++clock;
  block_bytes += size;
  // At most kMaxBlocksPerFactor per factor (every solve on it looks at all of them).
  size_t count = 0;
  auto oldest = blocks.end();
  for (auto b = blocks.lower_bound({it->first.first, 0}); b != blocks.end() && b->first.first == it->first.first; ++b) {
    ++count;
    if (b != it && (oldest == blocks.end() || b->second.last_use < oldest->second.last_use)) oldest = b;
  }
  if (count > kMaxBlocksPerFactor && oldest != blocks.end()) {
    block_bytes -= oldest->second.block->bytes;
    blocks.erase(oldest);
    ++evictions;
  }
  shrink(nullptr, &it->second);
  if (held() > budget) {  // larger than the whole budget
    block_bytes -= it->second.block->bytes;
    blocks.erase(it);
    ++evictions;
  }
}

uint64_t FactorCache::Impl::record_rows(uint64_t factor_id, const std::vector<uint64_t>& hashes,
                                        std::vector<uint64_t>& since) {
  std::lock_guard lock(mutex);
  const bool live = std::any_of(slots.begin(), slots.end(),
                                [&](const auto& s) { return s.second.ready && s.second.factor_id == factor_id; });
  if (!live) {  // a factor used for one solve only: nothing to remember
    since.assign(hashes.size(), 1);
    return 1;
  }
  History& h = history[factor_id];
  history_bytes -= std::min(history_bytes, h.bytes());
  const uint64_t now = ++h.solves;
  std::unordered_map<uint64_t, uint64_t> next;
  next.reserve(hashes.size());
  since.resize(hashes.size());
  for (size_t i = 0; i < hashes.size(); ++i) {
    const auto old = h.since.find(hashes[i]);
    since[i] = old != h.since.end() ? old->second : now;
    next.emplace(hashes[i], since[i]);
  }
  h.since = std::move(next);
  history_bytes += h.bytes();
  shrink(nullptr, nullptr);
  return now;
}

}  // namespace softshell::engine
