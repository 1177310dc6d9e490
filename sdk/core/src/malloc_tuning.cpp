#include "softshell/malloc_tuning.h"

#include <cstdlib>  // defines __GLIBC__ (through <features.h>) where the C library is glibc

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace softshell {

bool tune_malloc_for_solves() {
#if defined(__GLIBC__)
  constexpr int kMapFrom = 32 << 20;    // DEFAULT_MMAP_THRESHOLD_MAX on 64-bit glibc
  constexpr int kTrimAbove = 64 << 20;  // twice that, as glibc's adaptive rule sets it
  return ::mallopt(M_MMAP_THRESHOLD, kMapFrom) == 1 && ::mallopt(M_TRIM_THRESHOLD, kTrimAbove) == 1;
#else
  return false;
#endif
}

}  // namespace softshell
