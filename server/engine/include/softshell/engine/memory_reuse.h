#pragma once
// How the process's allocator treats the large blocks solves use (process-wide; opt-in).

namespace softshell::engine {

/// Asks the C library's allocator to keep freed memory for reuse: blocks below 32 MB come from
/// its heaps, and each heap keeps up to 64 MB of freed memory at its top, instead of giving it
/// back to the system to be faulted in again by the next solve. On a VM a fresh page costs
/// about 12 us (measured on the 2-core EPYC VM of docs/benchmarks.md), so a sparse
/// factorization whose temporaries arrive in fresh pages takes twice as long
/// (catmark_righthanded's tangent: 9 ms -> 21-25 ms). Process-wide, so the SDK never calls it on
/// its own: softshell-server, the demo and bench_engine do; a host that embeds the engine calls
/// it from its `main` if it wants the same, or sets
/// `GLIBC_TUNABLES=glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=67108864`.
/// An explicit malloc_trim still returns all free memory. Does nothing without glibc.
void keep_freed_memory_for_reuse();

}  // namespace softshell::engine
