// tune_malloc_for_solves (softshell/malloc_tuning.h): on glibc it takes effect, and blocks of
// megabytes freed and allocated again come from memory the process already has, where glibc's
// defaults give a freed heap top back to the system and fault it in anew.
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <vector>

#include <sys/resource.h>

#include "softshell/malloc_tuning.h"

namespace softshell {
namespace {

long minor_faults() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_minflt;
}

// Three 6 MiB buffers written and freed, as a solve's factor, matrix and state are; returns the
// pages faulted in meanwhile.
long faults_of_one_round() {
  constexpr size_t kBytes = size_t{6} << 20;
  const long before = minor_faults();
  std::vector<char*> blocks;
  for (int i = 0; i < 3; ++i) {
    char* block = static_cast<char*>(std::malloc(kBytes));
    if (block == nullptr) {
      ADD_FAILURE() << "out of memory";
      break;
    }
    std::memset(block, i + 1, kBytes);
    blocks.push_back(block);
  }
  for (auto it = blocks.rbegin(); it != blocks.rend(); ++it) std::free(*it);
  return minor_faults() - before;
}

TEST(MallocTuning, BlocksOfMegabytesAreReusedWithoutFaultingInAgain) {
#if !defined(__GLIBC__) || defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "tune_malloc_for_solves changes glibc's malloc only (a sanitizer brings its own)";
#else
  ASSERT_TRUE(tune_malloc_for_solves());
  (void)faults_of_one_round();  // the heap grows to hold them once
  // With glibc's defaults every round faults in its 4,608 pages: the first blocks are mapped and
  // unmapped, which raises the thresholds to 6 MiB (mapped from) and 12 MiB (trimmed above), so
  // the later ones come from the heap, whose free 18 MiB top then goes back to the system.
  EXPECT_LT(faults_of_one_round(), 200);
  EXPECT_LT(faults_of_one_round(), 200);
#endif
}

}  // namespace
}  // namespace softshell
