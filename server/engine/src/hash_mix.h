#pragma once
// One 64-bit hash step for the engine's content keys (factor patterns, constraint rows).

#include <cstdint>

namespace softshell::engine::internal {

/// Mixes `x` into the hash `h` (splitmix64 of x, folded into h).
inline uint64_t hash_mix(uint64_t h, uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL + (h << 6) + (h >> 2);
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  x ^= x >> 31;
  return h ^ x;
}

}  // namespace softshell::engine::internal
