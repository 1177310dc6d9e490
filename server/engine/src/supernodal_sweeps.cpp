// Triangular sweeps of a supernodal factor, on one thread and on two (see supernodal_sweeps.h).
// Both backends use it, the GPL-free one included: MPL-2.0 Eigen headers only.
#ifndef EIGEN_MPL2_ONLY
#define EIGEN_MPL2_ONLY
#endif
#include "supernodal_sweeps.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>

namespace softshell::engine::internal {

std::atomic<int64_t> g_two_thread_sweep_entries{int64_t{1} << 20};

namespace {

using ConstBlock = Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>>;

// Supernode s's block: L's own values, or (a single-precision factor) its values widened to double
// into a buffer of the calling thread, valid until its next call.
ConstBlock block_of(const SupernodalLayout& l, int64_t s) {
  const Eigen::Index ncols = l.first[s + 1] - l.first[s], nrows = l.row_start[s + 1] - l.row_start[s];
  if (!l.single) return ConstBlock(l.values + l.value_start[s], nrows, ncols, Eigen::OuterStride<>(nrows));
  thread_local std::vector<double> widened;
  const float* from = l.single + l.value_start[s];
  widened.assign(from, from + nrows * ncols);
  return ConstBlock(widened.data(), nrows, ncols, Eigen::OuterStride<>(nrows));
}

// The kernels of a single-precision factor's sweeps with one right-hand side: L's entries widened
// to double as they are read, every sum in double. Each is compiled twice, for x86-64-v3 (AVX2,
// FMA) and for the baseline, and picked once (sweep_kernels()). Not by target_clones: a local
// function's ifunc is resolved while the library is relocated, before a sanitizer's runtime is
// up, and ThreadSanitizer's instrumented resolver crashes there.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define SOFTSHELL_SWEEP_V3 1
#endif

using Wide = double __attribute__((vector_size(32)));
using Narrow = float __attribute__((vector_size(16)));

// (Always inlined: no call passes a vector across the two builds' ABIs.)
#pragma GCC diagnostic ignored "-Wpsabi"
[[gnu::always_inline]] inline Wide widen(const float* a) {
  Narrow n;
  std::memcpy(&n, a, sizeof n);
  return __builtin_convertvector(n, Wide);
}
[[gnu::always_inline]] inline Wide load(const double* a) {
  Wide w;
  std::memcpy(&w, a, sizeof w);
  return w;
}
[[gnu::always_inline]] inline void store(double* a, const Wide& w) { std::memcpy(a, &w, sizeof w); }
[[gnu::always_inline]] inline double sum_lanes(const Wide& w) { return (w[0] + w[1]) + (w[2] + w[3]); }

// y[0, n) += A (sign x), A's m columns `stride` apart (sign: +1 or -1, so y -= A x exactly as
// a subtraction would round). Four columns a pass: y is read and written a quarter as often.
[[gnu::always_inline]] inline void multiply_add_body(const float* a, int64_t stride, int64_t n, int64_t m,
                                                     const double* x, double sign, double* y) {
  int64_t k = 0;
  for (; k + 4 <= m; k += 4) {
    const float *a0 = a + k * stride, *a1 = a0 + stride, *a2 = a1 + stride, *a3 = a2 + stride;
    const double s0 = sign * x[k], s1 = sign * x[k + 1], s2 = sign * x[k + 2], s3 = sign * x[k + 3];
    const Wide x0 = Wide{} + s0, x1 = Wide{} + s1, x2 = Wide{} + s2, x3 = Wide{} + s3;
    int64_t i = 0;
    for (; i + 4 <= n; i += 4) {
      store(y + i, load(y + i) + ((widen(a0 + i) * x0 + widen(a1 + i) * x1) + (widen(a2 + i) * x2 + widen(a3 + i) * x3)));
    }
    for (; i < n; ++i) {
      y[i] += (static_cast<double>(a0[i]) * s0 + static_cast<double>(a1[i]) * s1) +
              (static_cast<double>(a2[i]) * s2 + static_cast<double>(a3[i]) * s3);
    }
  }
  for (; k < m; ++k) {
    const float* col = a + k * stride;
    const double sk = sign * x[k];
    const Wide xk = Wide{} + sk;
    int64_t i = 0;
    for (; i + 4 <= n; i += 4) store(y + i, load(y + i) + widen(col + i) * xk);
    for (; i < n; ++i) y[i] += static_cast<double>(col[i]) * sk;
  }
}

// y[0, m) -= A^T b, A (n x m) as above. Four columns a pass, each its own chain of sums.
[[gnu::always_inline]] inline void subtract_transposed_body(const float* a, int64_t stride, int64_t n, int64_t m,
                                                            const double* b, double* y) {
  int64_t k = 0;
  for (; k + 4 <= m; k += 4) {
    const float *a0 = a + k * stride, *a1 = a0 + stride, *a2 = a1 + stride, *a3 = a2 + stride;
    Wide d0{}, d1{}, d2{}, d3{};
    int64_t i = 0;
    for (; i + 4 <= n; i += 4) {
      const Wide bi = load(b + i);
      d0 += widen(a0 + i) * bi;
      d1 += widen(a1 + i) * bi;
      d2 += widen(a2 + i) * bi;
      d3 += widen(a3 + i) * bi;
    }
    double e0 = sum_lanes(d0), e1 = sum_lanes(d1), e2 = sum_lanes(d2), e3 = sum_lanes(d3);
    for (; i < n; ++i) {
      e0 += static_cast<double>(a0[i]) * b[i];
      e1 += static_cast<double>(a1[i]) * b[i];
      e2 += static_cast<double>(a2[i]) * b[i];
      e3 += static_cast<double>(a3[i]) * b[i];
    }
    y[k] -= e0;
    y[k + 1] -= e1;
    y[k + 2] -= e2;
    y[k + 3] -= e3;
  }
  for (; k < m; ++k) {
    const float* col = a + k * stride;
    Wide d0{}, d1{};
    int64_t i = 0;
    for (; i + 8 <= n; i += 8) {
      d0 += widen(col + i) * load(b + i);
      d1 += widen(col + i + 4) * load(b + i + 4);
    }
    double e = sum_lanes(d0 + d1);
    for (; i < n; ++i) e += static_cast<double>(col[i]) * b[i];
    y[k] -= e;
  }
}

using MultiplyAdd = void (*)(const float*, int64_t, int64_t, int64_t, const double*, double, double*);
using SubtractTransposed = void (*)(const float*, int64_t, int64_t, int64_t, const double*, double*);
struct SweepKernels {
  MultiplyAdd multiply_add;
  SubtractTransposed subtract_transposed;
};

void multiply_add_baseline(const float* a, int64_t stride, int64_t n, int64_t m, const double* x, double sign,
                           double* y) {
  multiply_add_body(a, stride, n, m, x, sign, y);
}
void subtract_transposed_baseline(const float* a, int64_t stride, int64_t n, int64_t m, const double* b, double* y) {
  subtract_transposed_body(a, stride, n, m, b, y);
}
#if defined(SOFTSHELL_SWEEP_V3)
[[gnu::target("arch=x86-64-v3")]] void multiply_add_v3(const float* a, int64_t stride, int64_t n, int64_t m,
                                                       const double* x, double sign, double* y) {
  multiply_add_body(a, stride, n, m, x, sign, y);
}
[[gnu::target("arch=x86-64-v3")]] void subtract_transposed_v3(const float* a, int64_t stride, int64_t n, int64_t m,
                                                              const double* b, double* y) {
  subtract_transposed_body(a, stride, n, m, b, y);
}
#endif

const SweepKernels& sweep_kernels() {
  static const SweepKernels kernels = [] {
#if defined(SOFTSHELL_SWEEP_V3)
    __builtin_cpu_init();
    if (__builtin_cpu_supports("x86-64-v3")) return SweepKernels{&multiply_add_v3, &subtract_transposed_v3};
#endif
    return SweepKernels{&multiply_add_baseline, &subtract_transposed_baseline};
  }();
  return kernels;
}

void multiply_add(const float* a, int64_t stride, int64_t n, int64_t m, const double* x, double sign, double* y) {
  sweep_kernels().multiply_add(a, stride, n, m, x, sign, y);
}
void subtract_transposed(const float* a, int64_t stride, int64_t n, int64_t m, const double* b, double* y) {
  sweep_kernels().subtract_transposed(a, stride, n, m, b, y);
}

// The diagonal blocks' triangular solves go by panels of this many columns: the small triangle
// of a panel by scalars, the rest of its columns by the four-column kernels above.
constexpr int64_t kPanel = 4;

// x[0, c) := T^-1 x, T the c x c lower triangle at `a` (columns `stride` apart).
void lower_solve(const float* a, int64_t stride, int64_t c, double* x) {
  for (int64_t j0 = 0; j0 < c; j0 += kPanel) {
    const int64_t end = std::min(c, j0 + kPanel);
    for (int64_t j = j0; j < end; ++j) {
      const float* col = a + j * stride;
      x[j] /= static_cast<double>(col[j]);
      for (int64_t i = j + 1; i < end; ++i) x[i] -= static_cast<double>(col[i]) * x[j];
    }
    if (end < c) multiply_add(a + j0 * stride + end, stride, c - end, end - j0, x + j0, -1.0, x + end);
  }
}

// x[0, c) := T^-T x.
void lower_transposed_solve(const float* a, int64_t stride, int64_t c, double* x) {
  for (int64_t j0 = (c - 1) / kPanel * kPanel; j0 >= 0; j0 -= kPanel) {
    const int64_t end = std::min(c, j0 + kPanel);
    if (end < c) subtract_transposed(a + j0 * stride + end, stride, c - end, end - j0, x + end, x + j0);
    for (int64_t j = end; j-- > j0;) {
      const float* col = a + j * stride;
      double sum = x[j];
      for (int64_t i = j + 1; i < end; ++i) sum -= static_cast<double>(col[i]) * x[i];
      x[j] = sum / static_cast<double>(col[j]);
    }
  }
}

template <class X>
constexpr bool kOneColumn = X::ColsAtCompileTime == 1;

// Supernode s's forward step: its columns of x solved with its diagonal block, then its rows below
// updated through `subtract(row, i, update)` (x.row(row) -= update.row(i) on one thread).
template <class X, class Subtract>
void forward_step_with(const SupernodalLayout& l, int64_t s, X& x, Subtract&& subtract) {
  const Eigen::Index ncols = l.first[s + 1] - l.first[s], nrows = l.row_start[s + 1] - l.row_start[s];
  thread_local X update;
  if constexpr (kOneColumn<X>) {
    if (l.single) {
      const float* a = l.single + l.value_start[s];
      double* xs = x.data() + l.first[s];
      lower_solve(a, nrows, ncols, xs);
      if (nrows == ncols) return;
      update.setZero(nrows - ncols);
      multiply_add(a + ncols, nrows, nrows - ncols, ncols, xs, 1.0, update.data());
      const int32_t* below = l.rows + l.row_start[s] + ncols;
      for (Eigen::Index i = 0; i < nrows - ncols; ++i) subtract(below[i], i, update);
      return;
    }
  }
  const ConstBlock block = block_of(l, s);
  auto xs = x.middleRows(l.first[s], ncols);
  block.topRows(ncols).template triangularView<Eigen::Lower>().solveInPlace(xs);
  if (nrows == ncols) return;
  update.noalias() = block.bottomRows(nrows - ncols) * xs;
  const int32_t* below = l.rows + l.row_start[s] + ncols;
  for (Eigen::Index i = 0; i < nrows - ncols; ++i) subtract(below[i], i, update);
}

}  // namespace

template <class X>
void forward_step(const SupernodalLayout& l, int64_t s, X& x) {
  forward_step_with(l, s, x, [&x](int32_t row, Eigen::Index i, const X& update) { x.row(row) -= update.row(i); });
}

template <class X>
void backward_step(const SupernodalLayout& l, int64_t s, X& x) {
  const Eigen::Index ncols = l.first[s + 1] - l.first[s], nrows = l.row_start[s + 1] - l.row_start[s];
  const int32_t* below = l.rows + l.row_start[s] + ncols;
  thread_local X gathered;
  if (nrows > ncols) {
    gathered.resize(nrows - ncols, x.cols());
    for (Eigen::Index i = 0; i < nrows - ncols; ++i) gathered.row(i) = x.row(below[i]);
  }
  if constexpr (kOneColumn<X>) {
    if (l.single) {
      const float* a = l.single + l.value_start[s];
      double* xs = x.data() + l.first[s];
      if (nrows > ncols) subtract_transposed(a + ncols, nrows, nrows - ncols, ncols, gathered.data(), xs);
      lower_transposed_solve(a, nrows, ncols, xs);
      return;
    }
  }
  const ConstBlock block = block_of(l, s);
  auto xs = x.middleRows(l.first[s], ncols);
  if (nrows > ncols) xs.noalias() -= block.bottomRows(nrows - ncols).transpose() * gathered;
  block.topRows(ncols).template triangularView<Eigen::Lower>().transpose().solveInPlace(xs);
}

template <class X>
void forward_sweep(const SupernodalLayout& l, X& x, const std::vector<char>& reached) {
  for (int64_t s = 0; s < l.supernodes; ++s) {
    if (reached[static_cast<size_t>(s)]) forward_step(l, s, x);
  }
}

template <class X>
void backward_sweep(const SupernodalLayout& l, X& x) {
  for (int64_t s = l.supernodes; s-- > 0;) backward_step(l, s, x);
}

std::unique_ptr<float[]> single_copy(const SupernodalLayout& l, const Eigen::SparseMatrix<double>& upper,
                                     double min_diagonal, Executor* executor) {
  // Well inside float's range (about 1e-38 to 3e38), so that sums of a few products stay in it too.
  constexpr double kLargest = 1e30, kSmallestPivot = 1e-30;
  const double largest_diagonal = upper.rows() > 0 ? upper.diagonal().maxCoeff() : 0.0;
  if (!(std::sqrt(largest_diagonal) < kLargest) || !(min_diagonal > kSmallestPivot)) return nullptr;
  const int64_t n = l.entries();
  std::unique_ptr<float[]> out(new float[static_cast<size_t>(std::max<int64_t>(n, 1))]);
  const int parts = executor && executor->concurrency() > 1 && n >= g_two_thread_sweep_entries.load() ? 2 : 1;
  auto convert = [&](int64_t part) {
    const int64_t begin = n * part / parts, end = n * (part + 1) / parts;
    for (int64_t i = begin; i < end; ++i) out[static_cast<size_t>(i)] = static_cast<float>(l.values[i]);
  };
  if (parts == 1) {
    convert(0);
  } else {
    executor->parallel_for(0, parts, convert, parts);
  }
  return out;
}

int64_t reach(const SupernodalLayout& l, std::vector<char>& reached, int64_t limit) {
  int64_t work = 0;
  for (int64_t s = 0; s < l.supernodes; ++s) {
    if (!reached[static_cast<size_t>(s)]) continue;
    const int64_t ncols = l.first[s + 1] - l.first[s];
    work += (l.row_start[s + 1] - l.row_start[s]) * ncols;
    if (work > limit) return work;
    for (int64_t p = l.row_start[s] + ncols; p < l.row_start[s + 1]; ++p) {
      reached[static_cast<size_t>(l.supernode_of[l.rows[p]])] = 1;
    }
  }
  return work;
}

ForwardSweep plan_forward(const SupernodalLayout& l, const TwoThreadSweeps* sweeps, const Executor* executor,
                          std::vector<char>& reached) {
  ForwardSweep f;
  const int64_t total = l.entries();
  f.work = reach(l, reached, total);
  f.whole = f.work > total / 2;
  f.two_threads = on_two_threads(sweeps, executor) && (f.whole || f.work >= g_two_thread_sweep_entries.load() / 4);
  return f;
}

std::unique_ptr<const TwoThreadSweeps> TwoThreadSweeps::plan(const SupernodalLayout& l) {
  const int64_t total = l.entries(), ns = l.supernodes;
  if (ns < 3 || total < g_two_thread_sweep_entries.load()) return nullptr;
  const auto count = static_cast<size_t>(ns);
  // The tree: a supernode's parent holds its first row below its columns (the parent comes later).
  std::vector<int32_t> parent(count, -1);
  std::vector<int64_t> subtree(count, 0), own(count, 0);
  std::vector<std::vector<int32_t>> children(count);
  std::vector<int32_t> frontier;  // roots of whole subtrees not yet given to a half
  for (int64_t s = 0; s < ns; ++s) {
    const int64_t ncols = l.first[s + 1] - l.first[s], nrows = l.row_start[s + 1] - l.row_start[s];
    own[static_cast<size_t>(s)] = nrows * ncols;
    subtree[static_cast<size_t>(s)] += own[static_cast<size_t>(s)];
    if (nrows > ncols) {
      const int32_t p = l.supernode_of[l.rows[l.row_start[s] + ncols]];
      if (p <= s) return nullptr;  // not an elimination tree in ascending order
      parent[static_cast<size_t>(s)] = p;
      subtree[static_cast<size_t>(p)] += subtree[static_cast<size_t>(s)];
      children[static_cast<size_t>(p)].push_back(static_cast<int32_t>(s));
    } else {
      frontier.push_back(static_cast<int32_t>(s));
    }
  }
  // Split the heaviest subtree (its root goes to the top) again and again, the subtrees dealt
  // largest first to the lighter half, and keep the split that sweeps fastest on two threads: the
  // least top plus larger half (a sweep reads memory at about the same rate on each thread). Stop
  // when the top would hold half the factor.
  std::vector<int32_t> top;
  std::vector<std::pair<int32_t, int8_t>> best_halves;  // the best split's subtree roots and halves
  size_t best_top = 0;
  int64_t best_time = total, top_work = 0;
  for (;;) {
    std::sort(frontier.begin(), frontier.end(),
              [&](int32_t a, int32_t b) { return subtree[static_cast<size_t>(a)] > subtree[static_cast<size_t>(b)]; });
    std::array<int64_t, 2> half{0, 0};
    std::vector<std::pair<int32_t, int8_t>> halves;
    for (int32_t root : frontier) {
      const int h = half[0] <= half[1] ? 0 : 1;
      half[static_cast<size_t>(h)] += subtree[static_cast<size_t>(root)];
      halves.emplace_back(root, static_cast<int8_t>(h));
    }
    const int64_t time = top_work + std::max(half[0], half[1]);
    if (time < best_time) {
      best_time = time;
      best_halves = std::move(halves);
      best_top = top.size();
    }
    const int32_t heaviest = frontier.front();
    if (children[static_cast<size_t>(heaviest)].empty()) break;
    top_work += own[static_cast<size_t>(heaviest)];
    // No later split beats the best once the top alone makes it slower (a split takes at least
    // top + (total - top) / 2).
    if (2 * top_work > total || total + top_work >= 2 * best_time) break;
    top.push_back(heaviest);
    frontier.erase(frontier.begin());
    frontier.insert(frontier.end(), children[static_cast<size_t>(heaviest)].begin(),
                    children[static_cast<size_t>(heaviest)].end());
  }
  // Worth a second thread only if the sweep gets 10% faster at least.
  if (10 * best_time > 9 * total) return nullptr;
  std::vector<int8_t> owner(count, -1);  // 0, 1: a half; 2: the top
  for (size_t i = 0; i < best_top; ++i) owner[static_cast<size_t>(top[i])] = 2;
  for (const auto& [root, h] : best_halves) owner[static_cast<size_t>(root)] = h;
  // Every other supernode goes with its parent (parents first: descending order).
  for (int64_t s = ns - 1; s >= 0; --s) {
    int8_t& o = owner[static_cast<size_t>(s)];
    if (o >= 0) continue;
    const int32_t p = parent[static_cast<size_t>(s)];
    if (p < 0 || owner[static_cast<size_t>(p)] < 0 || owner[static_cast<size_t>(p)] == 2) return nullptr;
    o = owner[static_cast<size_t>(p)];
  }
  // What the sweeps rely on: a supernode's rows below its columns are its own half's or the top's
  // (the top's: the top's only).
  for (int64_t s = 0; s < ns; ++s) {
    const int8_t o = owner[static_cast<size_t>(s)];
    const int64_t ncols = l.first[s + 1] - l.first[s];
    for (int64_t p = l.row_start[s] + ncols; p < l.row_start[s + 1]; ++p) {
      const int8_t r = owner[static_cast<size_t>(l.supernode_of[l.rows[p]])];
      if (r != 2 && r != o) return nullptr;
    }
  }
  std::unique_ptr<TwoThreadSweeps> plan(new TwoThreadSweeps());
  plan->top_index_.assign(static_cast<size_t>(l.columns()), -1);
  for (int64_t s = 0; s < ns; ++s) {
    const int8_t o = owner[static_cast<size_t>(s)];
    if (o < 2) {
      plan->halves_[static_cast<size_t>(o)].push_back(static_cast<int32_t>(s));
      continue;
    }
    plan->top_.push_back(static_cast<int32_t>(s));
    for (int32_t col = l.first[s]; col < l.first[s + 1]; ++col) {
      plan->top_index_[static_cast<size_t>(col)] = static_cast<int32_t>(plan->top_rows_.size());
      plan->top_rows_.push_back(col);
    }
  }
  int64_t top_entries = 0;
  for (int32_t t : plan->top_) top_entries += own[static_cast<size_t>(t)];
  plan->top_share_ = static_cast<double>(top_entries) / static_cast<double>(total);
  return plan;
}

template <class X>
void TwoThreadSweeps::forward(const SupernodalLayout& l, X& x, Executor& executor,
                              const std::vector<char>* reached) const {
  if (x.cols() == 0) return;
  const auto top_rows = static_cast<Eigen::Index>(top_rows_.size());
  // What each half subtracts from the top's rows, added to them once both are done.
  std::array<X, 2> gathered;
  executor.parallel_for(0, 2, [&](int64_t h) {
    X& into_top = gathered[static_cast<size_t>(h)];
    into_top.setZero(top_rows, x.cols());
    for (int32_t s : halves_[static_cast<size_t>(h)]) {
      if (reached && !(*reached)[static_cast<size_t>(s)]) continue;
      forward_step_with(l, s, x, [&](int32_t row, Eigen::Index i, const X& update) {
        const int32_t t = top_index_[static_cast<size_t>(row)];
        if (t >= 0) {
          into_top.row(t) += update.row(i);
        } else {
          x.row(row) -= update.row(i);
        }
      });
    }
  }, 2);
  for (Eigen::Index t = 0; t < top_rows; ++t) x.row(top_rows_[static_cast<size_t>(t)]) -= gathered[0].row(t) + gathered[1].row(t);
  for (int32_t s : top_) {
    if (!reached || (*reached)[static_cast<size_t>(s)]) forward_step(l, s, x);
  }
}

template <class X>
void TwoThreadSweeps::backward(const SupernodalLayout& l, X& x, Executor& executor) const {
  if (x.cols() == 0) return;
  for (auto s = top_.rbegin(); s != top_.rend(); ++s) backward_step(l, *s, x);
  executor.parallel_for(0, 2, [&](int64_t h) {
    const std::vector<int32_t>& half = halves_[static_cast<size_t>(h)];
    for (auto s = half.rbegin(); s != half.rend(); ++s) backward_step(l, *s, x);
  }, 2);
}

template void forward_step(const SupernodalLayout&, int64_t, Eigen::VectorXd&);
template void forward_step(const SupernodalLayout&, int64_t, Eigen::MatrixXd&);
template void backward_step(const SupernodalLayout&, int64_t, Eigen::VectorXd&);
template void backward_step(const SupernodalLayout&, int64_t, Eigen::MatrixXd&);
template void forward_sweep(const SupernodalLayout&, Eigen::VectorXd&, const std::vector<char>&);
template void forward_sweep(const SupernodalLayout&, Eigen::MatrixXd&, const std::vector<char>&);
template void backward_sweep(const SupernodalLayout&, Eigen::VectorXd&);
template void backward_sweep(const SupernodalLayout&, Eigen::MatrixXd&);
template void TwoThreadSweeps::forward(const SupernodalLayout&, Eigen::VectorXd&, Executor&,
                                       const std::vector<char>*) const;
template void TwoThreadSweeps::forward(const SupernodalLayout&, Eigen::MatrixXd&, Executor&,
                                       const std::vector<char>*) const;
template void TwoThreadSweeps::backward(const SupernodalLayout&, Eigen::VectorXd&, Executor&) const;
template void TwoThreadSweeps::backward(const SupernodalLayout&, Eigen::MatrixXd&, Executor&) const;

}  // namespace softshell::engine::internal
