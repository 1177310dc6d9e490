#pragma once
// The memory budget of everything the service keeps (private to the service).

#include <algorithm>
#include <cstddef>
#include <mutex>

namespace softshell::service::internal {

// Reservations are exact byte counts of what is stored (meshes, results, holds, followers) or
// estimates replaced by the real size (precomputed models).
class MemoryBudget {
 public:
  explicit MemoryBudget(size_t budget) : budget_(budget) {}
  bool try_reserve(size_t bytes) {
    std::lock_guard lock(mu_);
    if (bytes > budget_ || used_ > budget_ - bytes) return false;
    used_ += bytes;
    return true;
  }
  void release(size_t bytes) {
    std::lock_guard lock(mu_);
    used_ -= std::min(used_, bytes);
  }
  // Replaces a reservation by another size, even beyond the budget (a model that turned out
  // larger than estimated is kept; later requests are refused instead).
  void resize(size_t from, size_t to) {
    std::lock_guard lock(mu_);
    used_ = used_ - std::min(used_, from) + to;
  }
  size_t used() const {
    std::lock_guard lock(mu_);
    return used_;
  }
  size_t budget() const { return budget_; }

 private:
  mutable std::mutex mu_;
  size_t used_ = 0;
  const size_t budget_;
};

}  // namespace softshell::service::internal
