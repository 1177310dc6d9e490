// The numeric supernodal factorization's kernel (supernodal_numeric.h). CMake compiles this file
// twice: as it is (the baseline) and, with SOFTSHELL_KERNEL_X86_64_V3, for x86-64-v3 (AVX2, FMA:
// the dense blocks' products and the diagonal factorizations twice as fast). That copy gets its
// own name for Eigen's namespace, so that none of its template instances (AVX2 code) can stand in
// for the baseline's at link time; only the plain-typed entry point is shared.
#ifndef EIGEN_MPL2_ONLY
#define EIGEN_MPL2_ONLY  // the GPL-free build uses this file too
#endif
#ifdef SOFTSHELL_KERNEL_X86_64_V3
#define Eigen softshell_eigen_x86_64_v3
#define SOFTSHELL_KERNEL_ENTRY factor_x86_64_v3
#else
#define SOFTSHELL_KERNEL_ENTRY factor_baseline
#endif

#include "supernodal_numeric_kernel.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>

namespace softshell::engine::internal::supernodal_kernel {

using Block = Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>>;
using ConstBlock = Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>>;

// fn(0, split) and fn(split, end) on share's two threads.
template <class Fn>
void share_rows(const SupernodalShare& share, Eigen::Index split, Eigen::Index end, const Fn& fn) {
  auto band = [&](int part) { part == 0 ? fn(0, split) : fn(split, end); };
  share.run(share.context, [](void* argument, int part) { (*static_cast<decltype(band)*>(argument))(part); }, &band);
}

// fn(r0, r1) over rows [0, rows): as two bands on share's threads where there is a share, 96 rows
// or more and `flops` of work worth it; else fn(0, rows). The second band starts at a multiple of
// 24 rows, so Eigen gives every row the same micro-kernel (and the same sum order) as in one
// product or solve over all rows: its row blocks are multiples of its register tile (6 rows in
// the baseline build, 12 with AVX2), and its depth blocking depends on the depth alone.
template <class Fn>
void in_bands(const SupernodalShare* share, Eigen::Index rows, double flops, const Fn& fn) {
  if (share && rows >= 96 && flops >= share->min_flops) {
    share_rows(*share, (rows / 48) * 24, rows, fn);
  } else {
    fn(0, rows);
  }
}

// Eigen's blocked LLT (Eigen/src/Cholesky/LLT.h, llt_inplace<Scalar, Lower>::blocked) step by step,
// with its triangular solves and rank updates split into two bands of rows where `share` and the
// work allow. A band starts at a multiple of 24 rows (in_bands), and the rank update's second
// band is a product left of its diagonal block and a rank update on it: every entry is summed by
// the same micro-kernel in the same order as in the whole update (Eigen's row blocks there are
// multiples of its register tile but the last; its depth, the block size, is never blocked), so
// the factor is the same bit for bit. Returns the first column whose pivot is not positive, or -1.
template <class MatrixType>
Eigen::Index blocked_llt(MatrixType& m, const SupernodalShare* share) {
  using Eigen::Dynamic;
  using Eigen::Index;
  using Eigen::internal::llt_inplace;
  const Index size = m.rows();
  if (!share || size < 192) return llt_inplace<double, Eigen::Lower>::blocked(m);
  Index blockSize = size / 8;  // as Eigen's
  blockSize = (blockSize / 16) * 16;
  blockSize = std::min(std::max(blockSize, Index(8)), Index(128));
  for (Index k = 0; k < size; k += blockSize) {
    const Index bs = std::min(blockSize, size - k);
    const Index rs = size - k - bs;
    Eigen::Block<MatrixType, Dynamic, Dynamic> A11(m, k, k, bs, bs);
    Eigen::Block<MatrixType, Dynamic, Dynamic> A21(m, k + bs, k, rs, bs);
    Eigen::Block<MatrixType, Dynamic, Dynamic> A22(m, k + bs, k + bs, rs, rs);
    const Index ret = llt_inplace<double, Eigen::Lower>::unblocked(A11);
    if (ret >= 0) return k + ret;
    if (rs <= 0) continue;
    const bool shared = rs >= 96 && static_cast<double>(rs) * static_cast<double>(rs * bs) >= share->min_flops;
    if (!shared) {
      A11.adjoint().template triangularView<Eigen::Upper>().template solveInPlace<Eigen::OnTheRight>(A21);
      A22.template selfadjointView<Eigen::Lower>().rankUpdate(A21, -1.0);
      continue;
    }
    share_rows(*share, (rs / 48) * 24, rs, [&](Index r0, Index r1) {
      auto band = A21.middleRows(r0, r1 - r0);
      A11.adjoint().template triangularView<Eigen::Upper>().template solveInPlace<Eigen::OnTheRight>(band);
    });
    // The lower triangle's entries split about evenly: rows [0, s) hold s^2 / 2 of its rs^2 / 2.
    const Index s = std::max<Index>(24, static_cast<Index>(static_cast<double>(rs) * 0.7071 / 24.0) * 24);
    share_rows(*share, s, rs, [&](Index r0, Index r1) {
      if (r0 == 0) {
        A22.topLeftCorner(r1, r1).template selfadjointView<Eigen::Lower>().rankUpdate(A21.topRows(r1), -1.0);
      } else {
        A22.block(r0, 0, r1 - r0, r0).noalias() -= A21.middleRows(r0, r1 - r0) * A21.topRows(r0).transpose();
        A22.block(r0, r0, r1 - r0, r1 - r0).template selfadjointView<Eigen::Lower>().rankUpdate(
            A21.middleRows(r0, r1 - r0), -1.0);
      }
    });
  }
  return -1;
}

// Left-looking: supernode t gathers the updates of every descendant d with rows in t's columns
// (d waits in one of t's lists until then; `next_row` is where d's rows in t begin), then factors
// its diagonal block and solves for the rows below it.
SupernodalOutcome SOFTSHELL_KERNEL_ENTRY(const SupernodalLayout& l, const SupernodalInput& a, const int32_t* order,
                                         int64_t count, const SupernodalScratch* heads, int lists,
                                         SupernodalLinks links, double* values, const SupernodalShare* share) {
  SupernodalOutcome outcome;
  int32_t* const head = heads[0].head;
  int32_t* const map = heads[0].map;
  std::vector<double> update;  // the largest descendant update so far
  std::vector<int32_t> waiting;  // t's descendants, merged from several lists
  double low = std::numeric_limits<double>::infinity();
  // Puts d into target's list (in heads[0]) while t is factored.
  auto wait_for = [&](int32_t d, size_t target, int64_t t) {
    links.link[static_cast<size_t>(d)] = head[target];
    links.pushed_at[static_cast<size_t>(d)] = t;
    head[target] = d;
  };
  for (int64_t i_t = 0; i_t < count; ++i_t) {
    const auto t = static_cast<size_t>(order[i_t]);
    const int32_t k1 = l.first[t], k2 = l.first[t + 1];
    const Eigen::Index ncols = k2 - k1, nrows = l.row_start[t + 1] - l.row_start[t];
    const int32_t* rows = l.rows + l.row_start[t];
    for (Eigen::Index i = 0; i < nrows; ++i) map[static_cast<size_t>(rows[i])] = static_cast<int32_t>(i);
    double* block = values + l.value_start[t];
    std::fill(block, block + nrows * ncols, 0.0);
    Block lt(block, nrows, ncols, Eigen::OuterStride<>(nrows));
    for (int32_t j = k1; j < k2; ++j) {
      for (int64_t q = a.start[j]; q < a.start[j + 1]; ++q) lt(map[static_cast<size_t>(a.row[q])], j - k1) += a.a_values[a.value[q]];
    }
    // The descendants in the order one thread over the whole tree takes them: its single list,
    // last in first out, is the lists merged by when each was put in, the latest first.
    waiting.clear();
    if (lists == 1) {
      for (int32_t d = head[t]; d >= 0; d = links.link[static_cast<size_t>(d)]) waiting.push_back(d);
    } else {
      int32_t at[4] = {-1, -1, -1, -1};
      for (int h = 0; h < lists; ++h) at[h] = heads[h].head[t];
      for (;;) {
        int pick = -1;
        for (int h = 0; h < lists; ++h) {
          if (at[h] >= 0 && (pick < 0 || links.pushed_at[static_cast<size_t>(at[h])] >
                                             links.pushed_at[static_cast<size_t>(at[pick])])) {
            pick = h;
          }
        }
        if (pick < 0) break;
        waiting.push_back(at[pick]);
        at[pick] = links.link[static_cast<size_t>(at[pick])];
      }
      for (int h = 1; h < lists; ++h) heads[h].head[t] = -1;
    }
    head[t] = -1;
    for (const int32_t d : waiting) {
      const auto ds = static_cast<size_t>(d);
      const Eigen::Index d_rows = l.row_start[ds + 1] - l.row_start[ds], d_cols = l.first[ds + 1] - l.first[ds];
      const int32_t* drow = l.rows + l.row_start[ds];
      const int64_t from = links.next_row[ds];
      int64_t to = from;
      while (to < d_rows && drow[to] < k2) ++to;
      const Eigen::Index m1 = to - from, m2 = d_rows - from;  // rows in t's columns; rows from there down
      const ConstBlock ld(values + l.value_start[ds] + from, m2, d_cols, Eigen::OuterStride<>(d_rows));
      if (update.size() < static_cast<size_t>(m2 * m1)) update.resize(static_cast<size_t>(m2 * m1));
      Eigen::Map<Eigen::MatrixXd> c(update.data(), m2, m1);
      // The product and its scatter into t's columns, by bands of rows (each band's rows land in
      // rows of lt of their own).
      auto update_rows = [&](Eigen::Index r0, Eigen::Index r1) {
        if (r1 - r0 == m2) {  // (into c itself: a small product's coefficient-wise path depends on it)
          c.noalias() = ld * ld.topRows(m1).transpose();
        } else {
          c.middleRows(r0, r1 - r0).noalias() = ld.middleRows(r0, r1 - r0) * ld.topRows(m1).transpose();
        }
        for (Eigen::Index jj = 0; jj < m1; ++jj) {
          const Eigen::Index col = drow[from + jj] - k1;
          for (Eigen::Index ii = std::max(jj, r0); ii < r1; ++ii) lt(map[static_cast<size_t>(drow[from + ii])], col) -= c(ii, jj);
        }
      };
      in_bands(m1 >= 8 ? share : nullptr, m2, 2.0 * static_cast<double>(m2 * m1 * d_cols), update_rows);
      links.next_row[ds] = to;
      // d's next rows are in a later supernode: wait there.
      if (to < d_rows) wait_for(d, static_cast<size_t>(l.supernode_of[drow[to]]), static_cast<int64_t>(t));
    }
    auto diagonal = lt.topRows(ncols);
    const Eigen::Index bad = blocked_llt(diagonal, share);
    // Eigen's LLT stops at a pivot that is not positive but passes NaN through; a non-finite
    // value anywhere reaches a later pivot (L_kk^2 = A_kk - sum of squares of row k).
    Eigen::Index column = bad;
    if (column < 0) {
      for (Eigen::Index j = 0; j < ncols && column < 0; ++j) {
        if (!std::isfinite(diagonal(j, j))) column = j;
      }
      outcome.not_finite = column >= 0;
    }
    if (column >= 0) {
      outcome.failed_column = k1 + column;
      return outcome;
    }
    low = std::min(low, diagonal.diagonal().minCoeff());
    if (nrows > ncols) {
      const Eigen::Index n_below = nrows - ncols;
      // Each row of the rows below is solved on its own.
      in_bands(share, n_below, static_cast<double>(n_below * ncols * ncols), [&](Eigen::Index r0, Eigen::Index r1) {
        auto band = lt.middleRows(ncols + r0, r1 - r0);
        diagonal.triangularView<Eigen::Lower>().transpose().solveInPlace<Eigen::OnTheRight>(band);
      });
      links.next_row[t] = ncols;
      wait_for(static_cast<int32_t>(t), static_cast<size_t>(l.supernode_of[rows[ncols]]), static_cast<int64_t>(t));
    }
  }
  outcome.min_diagonal = low;
  return outcome;
}

}  // namespace softshell::engine::internal::supernodal_kernel
