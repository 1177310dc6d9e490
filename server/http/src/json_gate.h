#pragma once
// Bounds the bytes of JSON bodies decoded at once (their DOM takes many times their size).

#include <malloc.h>

#include <atomic>
#include <cstddef>

namespace softshell::http::internal {

class JsonGate {
 public:
  static constexpr size_t kTrimAbove = size_t{256} << 20;  // decode memory, bytes
  explicit JsonGate(size_t budget) : budget_(budget) {}
  bool enter(size_t bytes) {
    size_t used = used_.load();
    do {
      if (bytes > budget_ || used > budget_ - bytes) return false;
    } while (!used_.compare_exchange_weak(used, used + bytes));
    return true;
  }
  // Returns the memory of a large decode to the system: glibc keeps the freed DOM's many small
  // blocks in its arenas, where they would stay resident (gigabytes after a few large bodies).
  void leave(size_t bytes) {
    used_.fetch_sub(bytes);
    if (bytes >= kTrimAbove) ::malloc_trim(0);
  }
  size_t budget() const { return budget_; }

 private:
  const size_t budget_;
  std::atomic<size_t> used_{0};
};

}  // namespace softshell::http::internal
