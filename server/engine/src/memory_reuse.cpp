#include "softshell/engine/memory_reuse.h"

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace softshell::engine {

void keep_freed_memory_for_reuse() {
#if defined(__GLIBC__)
  // Fixed thresholds also turn off glibc's own adjustment of them (which follows the sizes freed).
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
  mallopt(M_TRIM_THRESHOLD, 64 << 20);
#endif
}

}  // namespace softshell::engine
