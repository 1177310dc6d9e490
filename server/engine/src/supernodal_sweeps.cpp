// Triangular sweeps of a supernodal factor, on one thread and on two (see supernodal_sweeps.h).
// Both backends use it, the GPL-free one included: MPL-2.0 Eigen headers only.
#ifndef EIGEN_MPL2_ONLY
#define EIGEN_MPL2_ONLY
#endif
#include "supernodal_sweeps.h"

#include <algorithm>
#include <cstdlib>

namespace softshell::engine::internal {

std::atomic<int64_t> g_two_thread_sweep_entries{int64_t{1} << 20};

namespace {

using ConstBlock = Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>>;

ConstBlock block_of(const SupernodalLayout& l, int64_t s) {
  const Eigen::Index ncols = l.first[s + 1] - l.first[s], nrows = l.row_start[s + 1] - l.row_start[s];
  return ConstBlock(l.values + l.value_start[s], nrows, ncols, Eigen::OuterStride<>(nrows));
}

// Supernode s's forward step: its columns of x solved with its diagonal block, then its rows below
// updated through `subtract(row, i, update)` (x.row(row) -= update.row(i) on one thread).
template <class X, class Subtract>
void forward_step_with(const SupernodalLayout& l, int64_t s, X& x, Subtract&& subtract) {
  const ConstBlock block = block_of(l, s);
  const Eigen::Index ncols = block.cols(), nrows = block.rows();
  auto xs = x.middleRows(l.first[s], ncols);
  block.topRows(ncols).template triangularView<Eigen::Lower>().solveInPlace(xs);
  if (nrows == ncols) return;
  thread_local X update;
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
  const ConstBlock block = block_of(l, s);
  const Eigen::Index ncols = block.cols(), nrows = block.rows();
  auto xs = x.middleRows(l.first[s], ncols);
  if (nrows > ncols) {
    thread_local X gathered;
    gathered.resize(nrows - ncols, x.cols());
    const int32_t* below = l.rows + l.row_start[s] + ncols;
    for (Eigen::Index i = 0; i < nrows - ncols; ++i) gathered.row(i) = x.row(below[i]);
    xs.noalias() -= block.bottomRows(nrows - ncols).transpose() * gathered;
  }
  block.topRows(ncols).template triangularView<Eigen::Lower>().transpose().solveInPlace(xs);
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
template void TwoThreadSweeps::forward(const SupernodalLayout&, Eigen::VectorXd&, Executor&,
                                       const std::vector<char>*) const;
template void TwoThreadSweeps::forward(const SupernodalLayout&, Eigen::MatrixXd&, Executor&,
                                       const std::vector<char>*) const;
template void TwoThreadSweeps::backward(const SupernodalLayout&, Eigen::VectorXd&, Executor&) const;
template void TwoThreadSweeps::backward(const SupernodalLayout&, Eigen::MatrixXd&, Executor&) const;

}  // namespace softshell::engine::internal
