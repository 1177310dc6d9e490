#pragma once
// The numeric kernel of supernodal_numeric.h, built twice (supernodal_numeric_kernel.cpp): plain
// types only, so that the copy compiled for x86-64-v3 shares nothing with the rest but this.

#include <cstdint>
#include <limits>

#include "supernodal_layout.h"

namespace softshell::engine::internal {

struct SupernodalOutcome {
  int64_t failed_column = -1;  ///< first factor column whose pivot was not positive (or not finite); -1 if none
  bool not_finite = false;     ///< that pivot was NaN or infinite
  double min_diagonal = std::numeric_limits<double>::infinity();  ///< min L_kk, when it succeeded
};

namespace supernodal_kernel {

/// factor_supernodes (supernodal_numeric.h) with A's entries as plain arrays: the baseline build
/// and, where the compiler could build it (SOFTSHELL_X86_64_V3_KERNELS), the x86-64-v3 one.
SupernodalOutcome factor_baseline(const SupernodalLayout& layout, const int64_t* start, const int32_t* row,
                                  const int32_t* value, const double* a_values, double* values);
SupernodalOutcome factor_x86_64_v3(const SupernodalLayout& layout, const int64_t* start, const int32_t* row,
                                   const int32_t* value, const double* a_values, double* values);

}  // namespace supernodal_kernel
}  // namespace softshell::engine::internal
