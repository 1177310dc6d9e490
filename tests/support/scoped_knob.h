#pragma once
// Sets one of the engine's test knobs (an std::atomic the tests reach: a size threshold, a hook)
// for a scope, then puts its earlier value back, also when an assertion leaves the scope early.

#include <atomic>

namespace softshell::test {

template <class T>
class ScopedKnob {
 public:
  ScopedKnob(std::atomic<T>& knob, T value) : knob_(knob), before_(knob.exchange(value)) {}
  ~ScopedKnob() { knob_.store(before_); }
  ScopedKnob(const ScopedKnob&) = delete;
  ScopedKnob& operator=(const ScopedKnob&) = delete;

 private:
  std::atomic<T>& knob_;
  T before_;
};

}  // namespace softshell::test
