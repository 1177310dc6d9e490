#pragma once
// Small helpers shared by the benchmarks: timing, statistics, machine description, malloc.
#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <sys/resource.h>

#include "softshell/malloc_tuning.h"

namespace softshell::bench {

using Clock = std::chrono::steady_clock;
inline double ms_since(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

inline double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const auto i = static_cast<size_t>(p * static_cast<double>(v.size() - 1) + 0.5);
  return v[std::min(i, v.size() - 1)];
}

/// "model name, N cores" from /proc/cpuinfo (for the README's "machine" line).
inline std::string machine() {
  std::ifstream cpu("/proc/cpuinfo");
  std::string line, model = "unknown CPU";
  while (std::getline(cpu, line)) {
    if (line.rfind("model name", 0) == 0) {
      model = line.substr(line.find(':') + 2);
      break;
    }
  }
  return model + ", " + std::to_string(std::thread::hardware_concurrency()) + " threads";
}

/// Pages faulted in so far (on a VM each fresh page costs microseconds: docs/benchmarks.md).
inline long minor_faults() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_minflt;
}

/// malloc as softshell-server sets it (tune_malloc_for_solves), unless the environment has
/// SOFTSHELL_BENCH_DEFAULT_MALLOC (glibc's defaults). Call first thing in main.
inline void malloc_as_the_server() {
  if (std::getenv("SOFTSHELL_BENCH_DEFAULT_MALLOC") == nullptr) tune_malloc_for_solves();
}

}  // namespace softshell::bench
