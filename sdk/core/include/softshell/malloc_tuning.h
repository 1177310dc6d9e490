#pragma once
/// \file
/// \brief `tune_malloc_for_solves`: glibc's malloc settings for a process that solves often.
///
/// A solve allocates buffers of megabytes again and again: sparse factors and tangent matrices,
/// the nonlinear model's states (tens of MB on a large mesh). glibc serves such blocks from
/// memory it maps for each and unmaps when they are freed, or gives a freed heap top back to the
/// system, so each time the next buffer's pages fault in anew; on a VM a fresh page costs about
/// 12 us. Measured on catmark_righthanded's nonlinear drag (docs/benchmarks.md, fifth session):
/// the pull from rest faulted in 1,000-2,800 pages (323-394 ms; none and 304-342 ms with this),
/// and preconditioner refreshes that faulted took 30-40 ms instead of 18-19 ms.
///
/// softshell-server, the demo, bench_engine and bench_soak call this at start. A host that embeds
/// the SDK decides for its own process: call it early in `main`, or start the process with
/// `GLIBC_TUNABLES=glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=67108864`
/// (the same settings), or leave malloc as it is (answers to the same tolerance, slower).

namespace softshell {

/// Keeps freed memory for reuse: blocks below 32 MiB come from the heap instead of their own
/// mappings, and up to 64 MiB free at the top of a heap stay with the process (glibc's own
/// upper limits for the thresholds it otherwise adapts on the way). Process-wide and meant to be
/// called once, before other threads allocate. Returns whether glibc took both settings: false
/// where malloc is not glibc's (another C library, or a sanitizer's allocator).
bool tune_malloc_for_solves();

}  // namespace softshell
