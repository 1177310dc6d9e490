#pragma once
// Bounds the bytes of JSON bodies decoded at once (their DOM takes many times their size).

#include <atomic>
#include <cstddef>

namespace softshell::http::internal {

class JsonGate {
 public:
  explicit JsonGate(size_t budget) : budget_(budget) {}
  bool enter(size_t bytes) {
    size_t used = used_.load();
    do {
      if (bytes > budget_ || used > budget_ - bytes) return false;
    } while (!used_.compare_exchange_weak(used, used + bytes));
    return true;
  }
  void leave(size_t bytes) { used_.fetch_sub(bytes); }

 private:
  const size_t budget_;
  std::atomic<size_t> used_{0};
};

}  // namespace softshell::http::internal
