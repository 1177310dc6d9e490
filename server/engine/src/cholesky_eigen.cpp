// The GPL-free implementation of CholeskyFactor (SOFTSHELL_SPARSE_CHOLESKY=eigen): a supernodal
// left-looking L L^T on Eigen's approximate-minimum-degree ordering, on Eigen's dense kernels: the
// symbolic analysis here, the numeric factorization (which the CHOLMOD build runs too) in
// supernodal_numeric.h. Only MPL-2.0 Eigen headers are used (EIGEN_MPL2_ONLY makes the compiler
// refuse any other); no BLAS, no SuiteSparse.
//
// Why not Eigen's SimplicialLLT: a simplicial (column-by-column, scalar) factorization measured
// 4-9x slower than CHOLMOD's supernodal one on the shipped meshes, and its sweeps 3-4x slower;
// columns with the same structure grouped into dense blocks (supernodes) let the work run as
// dense matrix products. The method is the classical one (Liu's elimination tree, supernodes with
// relaxed amalgamation, left-looking updates from descendant supernodes), as in Ng & Peyton 1993
// and Davis's CHOLMOD; the code is ours. The layout of L is CHOLMOD's supernodal one (per
// supernode a dense column-major block: its columns' rows, diagonal block first), so the sweeps
// are the ones both backends share (supernodal_sweeps.h).
//
// File length: ~400 lines: the symbolic analysis, the factor's state and its sweeps.
#ifndef EIGEN_MPL2_ONLY
#define EIGEN_MPL2_ONLY
#endif
#include "cholesky_factor.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <new>
#include <vector>

#include <Eigen/OrderingMethods>

#include "supernodal_numeric.h"
#include "supernodal_sweeps.h"

namespace softshell::engine::internal {

std::atomic<size_t> g_spare_factor_bytes{8u << 20};  // the CHOLMOD build's (cholesky_factor.h)

namespace {

// Supernodes are merged with their parent while the merged block stays small or mostly nonzero
// (CHOLMOD's defaults): up to 4 columns always, up to 16 with < 80% explicit zeros, up to 48
// with < 10%, any size with < 5%.
constexpr int kRelaxColumns[3] = {4, 16, 48};
constexpr double kRelaxZeros[3] = {0.8, 0.1, 0.05};

// Everything that depends on A's pattern only; shared by every factor of that pattern.
struct Symbolic {
  Eigen::Index n = 0;
  Eigen::Index a_nonzeros = 0;    // of the upper triangle given to factorize()
  std::vector<int32_t> position;  // position[i]: where row i of A is in the factor (P)
  std::vector<int32_t> original;  // original[k]: the row of A at factor position k (P^T)
  // Supernode s: columns first[s] .. first[s + 1] - 1; its rows (its own columns first, then the
  // rows below, ascending) are rows[row_start[s] .. row_start[s + 1]); its values a column-major
  // block at value_start[s].
  std::vector<int32_t> first, supernode_of, rows;
  std::vector<int64_t> row_start, value_start;
  std::unique_ptr<const TwoThreadSweeps> sweeps;  // the plan for sweeps on two threads, if any

  size_t supernodes() const { return first.size() - 1; }
  size_t bytes() const {
    return (position.size() + original.size() + first.size() + supernode_of.size() + rows.size()) * sizeof(int32_t) +
           (row_start.size() + value_start.size()) * sizeof(int64_t) + sizeof(Symbolic) + (sweeps ? sweeps->bytes() : 0);
  }
};

SupernodalLayout layout(const Symbolic& s, const double* values) {
  SupernodalLayout l;
  l.supernodes = static_cast<int64_t>(s.supernodes());
  l.first = s.first.data();
  l.row_start = s.row_start.data();
  l.value_start = s.value_start.data();
  l.rows = s.rows.data();
  l.supernode_of = s.supernode_of.data();
  l.values = values;
  return l;
}

// Postorder of a forest given by `parent` (-1: a root): children before their parent, each
// subtree contiguous.
std::vector<int32_t> postorder(const std::vector<int32_t>& parent) {
  const auto n = parent.size();
  std::vector<int32_t> head(n, -1), next(n, -1), order, stack;
  order.reserve(n);
  for (size_t j = n; j-- > 0;) {  // children lists, ascending
    if (parent[j] < 0) continue;
    next[j] = head[static_cast<size_t>(parent[j])];
    head[static_cast<size_t>(parent[j])] = static_cast<int32_t>(j);
  }
  for (size_t root = 0; root < n; ++root) {
    if (parent[root] >= 0) continue;
    stack.push_back(static_cast<int32_t>(root));
    while (!stack.empty()) {
      const auto top = static_cast<size_t>(stack.back());
      if (const int32_t child = head[top]; child >= 0) {
        head[top] = next[static_cast<size_t>(child)];
        stack.push_back(child);
      } else {
        stack.pop_back();
        order.push_back(static_cast<int32_t>(top));
      }
    }
  }
  return order;
}

// Strict upper pattern (rows i < k of column k) of P A P^T for the ordering `position`.
void upper_pattern(const Eigen::SparseMatrix<double>& upper, const std::vector<int32_t>& position,
                   std::vector<int64_t>& start, std::vector<int32_t>& row) {
  const auto n = static_cast<size_t>(upper.rows());
  start.assign(n + 1, 0);
  for (Eigen::Index j = 0; j < upper.cols(); ++j) {
    for (int p = upper.outerIndexPtr()[j]; p < upper.outerIndexPtr()[j + 1]; ++p) {
      const Eigen::Index i = upper.innerIndexPtr()[p];
      if (i >= j) continue;
      ++start[static_cast<size_t>(std::max(position[static_cast<size_t>(i)], position[static_cast<size_t>(j)])) + 1];
    }
  }
  for (size_t k = 0; k < n; ++k) start[k + 1] += start[k];
  row.resize(static_cast<size_t>(start[n]));
  std::vector<int64_t> next(start.begin(), start.end() - 1);
  for (Eigen::Index j = 0; j < upper.cols(); ++j) {
    for (int p = upper.outerIndexPtr()[j]; p < upper.outerIndexPtr()[j + 1]; ++p) {
      const Eigen::Index i = upper.innerIndexPtr()[p];
      if (i >= j) continue;
      const int32_t pi = position[static_cast<size_t>(i)], pj = position[static_cast<size_t>(j)];
      row[static_cast<size_t>(next[static_cast<size_t>(std::max(pi, pj))]++)] = std::min(pi, pj);
    }
  }
}

// Elimination tree of the matrix whose strict upper pattern is (start, row) (Liu, with path
// compression through `ancestor`).
std::vector<int32_t> elimination_tree(const std::vector<int64_t>& start, const std::vector<int32_t>& row) {
  const size_t n = start.size() - 1;
  std::vector<int32_t> parent(n, -1), ancestor(n, -1);
  for (size_t k = 0; k < n; ++k) {
    for (int64_t q = start[k]; q < start[k + 1]; ++q) {
      for (int32_t i = row[static_cast<size_t>(q)]; i >= 0 && static_cast<size_t>(i) < k;) {
        const int32_t up = ancestor[static_cast<size_t>(i)];
        ancestor[static_cast<size_t>(i)] = static_cast<int32_t>(k);
        if (up < 0) parent[static_cast<size_t>(i)] = static_cast<int32_t>(k);
        i = up;
      }
    }
  }
  return parent;
}

// The symbolic analysis of `upper`; `a` gets A's entries in the factor's order (which it reads).
std::shared_ptr<const Symbolic> analyze(const Eigen::SparseMatrix<double>& upper, FactorOrderEntries& a) {
  auto s = std::make_shared<Symbolic>();
  const Eigen::Index n = upper.rows();
  const auto un = static_cast<size_t>(n);
  s->n = n;
  s->a_nonzeros = upper.nonZeros();

  // Fill-reducing ordering (AMD on the symmetric pattern; Eigen's gives P^T), then the
  // elimination tree's postorder on top of it, so that every subtree is a range of columns.
  std::vector<int32_t> amd(un), position(un);
  {
    Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> order;
    Eigen::AMDOrdering<int>()(upper.selfadjointView<Eigen::Upper>(), order);
    for (size_t k = 0; k < un; ++k) amd[k] = order.indices()[static_cast<Eigen::Index>(k)];
  }
  for (size_t k = 0; k < un; ++k) position[static_cast<size_t>(amd[k])] = static_cast<int32_t>(k);
  std::vector<int64_t> up_start;
  std::vector<int32_t> up_row;
  upper_pattern(upper, position, up_start, up_row);
  const std::vector<int32_t> post = postorder(elimination_tree(up_start, up_row));
  s->original.resize(un);
  for (size_t k = 0; k < un; ++k) s->original[k] = amd[static_cast<size_t>(post[k])];
  s->position.resize(un);
  for (size_t k = 0; k < un; ++k) s->position[static_cast<size_t>(s->original[k])] = static_cast<int32_t>(k);
  upper_pattern(upper, s->position, up_start, up_row);
  const std::vector<int32_t> parent = elimination_tree(up_start, up_row);

  // Column counts of L (diagonal included): row k of L is the union of the tree paths from the
  // rows of column k up to k.
  std::vector<int32_t> count(un, 1), tag(un, -1), children(un, 0);
  for (size_t k = 0; k < un; ++k) {
    tag[k] = static_cast<int32_t>(k);
    for (int64_t q = up_start[k]; q < up_start[k + 1]; ++q) {
      for (auto i = static_cast<size_t>(up_row[static_cast<size_t>(q)]); tag[i] != static_cast<int32_t>(k);
           i = static_cast<size_t>(parent[i])) {
        ++count[i];
        tag[i] = static_cast<int32_t>(k);
      }
    }
    if (parent[k] >= 0) ++children[static_cast<size_t>(parent[k])];
  }
  // Fundamental supernodes: column j joins j - 1's when it is its only child in the tree and
  // L's column j - 1 is column j's pattern plus one row.
  std::vector<int32_t> first;
  for (size_t j = 0; j < un; ++j) {
    const bool extends = j > 0 && parent[j - 1] == static_cast<int32_t>(j) && count[j - 1] == count[j] + 1 && children[j] == 1;
    if (!extends) first.push_back(static_cast<int32_t>(j));
  }
  first.push_back(static_cast<int32_t>(n));
  // Relaxed amalgamation, from the last supernode down: s merges into s + 1 (its parent, and
  // next in postorder) when the merged block has few explicit zeros.
  const size_t nf = first.size() - 1;
  std::vector<int32_t> fs_of(un);
  for (size_t f = 0; f < nf; ++f) {
    for (int32_t j = first[f]; j < first[f + 1]; ++j) fs_of[static_cast<size_t>(j)] = static_cast<int32_t>(f);
  }
  std::vector<int64_t> columns(nf), height(nf), zeros(nf, 0);
  std::vector<char> merged_into_previous(nf, 0);
  for (size_t f = 0; f < nf; ++f) {
    columns[f] = first[f + 1] - first[f];
    height[f] = count[static_cast<size_t>(first[f])];
  }
  for (size_t f = nf - 1; f-- > 0;) {
    const int32_t last = first[f + 1] - 1;
    if (parent[static_cast<size_t>(last)] < 0 || fs_of[static_cast<size_t>(parent[static_cast<size_t>(last)])] != static_cast<int32_t>(f + 1)) continue;
    const int64_t c0 = columns[f], c1 = columns[f + 1], merged_columns = c0 + c1;
    const int64_t merged_height = height[f + 1] + c0;
    const int64_t new_zeros = c0 * (merged_height - height[f]);
    const int64_t total_zeros = zeros[f] + zeros[f + 1] + new_zeros;
    const double entries = static_cast<double>(merged_columns * (merged_columns + 1) / 2 +
                                               merged_columns * (merged_height - merged_columns));
    const double share = static_cast<double>(total_zeros) / entries;
    const bool merge = new_zeros == 0 || merged_columns <= kRelaxColumns[0] ||
                       (merged_columns <= kRelaxColumns[1] && share < kRelaxZeros[0]) ||
                       (merged_columns <= kRelaxColumns[2] && share < kRelaxZeros[1]) || share < kRelaxZeros[2];
    if (!merge) continue;
    columns[f] = merged_columns;
    height[f] = merged_height;
    zeros[f] = total_zeros;
    merged_into_previous[f + 1] = 1;
  }
  s->first.clear();
  for (size_t f = 0; f < nf; ++f) {
    if (!merged_into_previous[f]) s->first.push_back(first[f]);
  }
  s->first.push_back(static_cast<int32_t>(n));
  const size_t ns = s->supernodes();
  s->supernode_of.resize(un);
  for (size_t t = 0; t < ns; ++t) {
    for (int32_t j = s->first[t]; j < s->first[t + 1]; ++j) s->supernode_of[static_cast<size_t>(j)] = static_cast<int32_t>(t);
  }

  a = factor_order_entries(upper, s->position);

  // Each supernode's rows: its columns, then A's rows below them and its children's rows below
  // them (a child: a supernode whose first row below its own columns falls in this one).
  std::vector<int32_t> child_head(ns, -1), child_next(ns, -1), below;
  std::fill(tag.begin(), tag.end(), -1);
  s->row_start.assign(1, 0);
  s->value_start.assign(1, 0);
  for (size_t t = 0; t < ns; ++t) {
    const int32_t k1 = s->first[t], k2 = s->first[t + 1];
    below.clear();
    auto add = [&](int32_t i) {
      if (i >= k2 && tag[static_cast<size_t>(i)] != static_cast<int32_t>(t)) {
        tag[static_cast<size_t>(i)] = static_cast<int32_t>(t);
        below.push_back(i);
      }
    };
    for (int32_t j = k1; j < k2; ++j) {
      for (int64_t q = a.start[static_cast<size_t>(j)]; q < a.start[static_cast<size_t>(j) + 1]; ++q) add(a.row[static_cast<size_t>(q)]);
    }
    for (int32_t c = child_head[t]; c >= 0; c = child_next[static_cast<size_t>(c)]) {
      const auto cs = static_cast<size_t>(c);
      const int64_t own = s->first[cs + 1] - s->first[cs];
      for (int64_t p = s->row_start[cs] + own; p < s->row_start[cs + 1]; ++p) add(s->rows[static_cast<size_t>(p)]);
    }
    std::sort(below.begin(), below.end());
    for (int32_t j = k1; j < k2; ++j) s->rows.push_back(j);
    s->rows.insert(s->rows.end(), below.begin(), below.end());
    const auto nrows = static_cast<int64_t>(k2 - k1) + static_cast<int64_t>(below.size());
    s->row_start.push_back(s->row_start.back() + nrows);
    s->value_start.push_back(s->value_start.back() + nrows * (k2 - k1));
    if (!below.empty()) {
      const auto p = static_cast<size_t>(s->supernode_of[static_cast<size_t>(below.front())]);
      child_next[t] = child_head[p];
      child_head[p] = static_cast<int32_t>(t);
    }
  }
  s->rows.shrink_to_fit();
  s->sweeps = TwoThreadSweeps::plan(layout(*s, nullptr));
  return s;
}

}  // namespace

struct CholeskyFactor::State {
  std::shared_ptr<const Symbolic> symbolic;
  std::vector<double> values;  // the supernodes' blocks
  std::unique_ptr<float[]> single;  // L rounded to single precision (SweepPrecision::kSingle)
  SupernodalLayout layout() const {
    SupernodalLayout l = softshell::engine::internal::layout(*symbolic, values.data());
    l.single = single.get();
    return l;
  }
  double min_pivot = 0.0;
};

CholeskyFactor::CholeskyFactor(std::unique_ptr<State> state) : state_(std::move(state)) {}
CholeskyFactor::~CholeskyFactor() = default;

const char* CholeskyFactor::backend() { return "supernodal LL^T on Eigen's AMD (GPL-free)"; }

std::unique_ptr<CholeskyFactor> CholeskyFactor::factorize(const Eigen::SparseMatrix<double>& upper,
                                                          const CholeskyFactor* same_pattern, Failure& failure,
                                                          Executor* executor, SweepPrecision precision) {
  failure = Failure{};
  try {
    auto state = std::make_unique<State>();
    const Symbolic* known = same_pattern ? same_pattern->state_->symbolic.get() : nullptr;
    FactorOrderEntries entries;
    if (known && known->n == upper.rows() && known->a_nonzeros == upper.nonZeros()) {
      state->symbolic = same_pattern->state_->symbolic;
      entries = factor_order_entries(upper, known->position);
    } else {
      state->symbolic = analyze(upper, entries);
    }
    const Symbolic& s = *state->symbolic;
    state->values.resize(static_cast<size_t>(s.value_start.back()));
    const SupernodalOutcome outcome =
        factor_supernodes(layout(s, nullptr), entries, upper.valuePtr(), state->values.data(), s.sweeps.get(), executor);
    if (outcome.failed_column >= 0) {
      failure.column = s.original[static_cast<size_t>(outcome.failed_column)];
      failure.not_finite = outcome.not_finite;
      return nullptr;
    }
    state->min_pivot = outcome.min_diagonal * outcome.min_diagonal;
    if (precision == SweepPrecision::kSingle) state->single = single_copy(state->layout(), upper, outcome.min_diagonal, executor);
    return std::unique_ptr<CholeskyFactor>(new CholeskyFactor(std::move(state)));
  } catch (const std::bad_alloc&) {
    failure.out_of_memory = true;
    return nullptr;
  }
}

Eigen::Index CholeskyFactor::size() const { return state_->symbolic->n; }

size_t CholeskyFactor::bytes() const {
  return state_->symbolic->bytes() + state_->values.size() * (sizeof(double) + (state_->single ? sizeof(float) : 0)) +
         sizeof(State);
}

double CholeskyFactor::min_pivot() const { return state_->min_pivot; }

bool CholeskyFactor::two_thread_sweeps() const { return state_->symbolic->sweeps != nullptr; }

bool CholeskyFactor::single_precision_sweeps() const { return state_->single != nullptr; }

Eigen::MatrixXd CholeskyFactor::forward(const Eigen::MatrixXd& rhs, double* fraction_read, Executor* executor) const {
  const Symbolic& s = *state_->symbolic;
  const SupernodalLayout l = state_->layout();
  // P B, and the supernodes holding its nonzero rows: the sweep starts there and reaches every
  // supernode one of them updates, in ascending order (on two threads where plan_forward says
  // so).
  std::vector<char> reached(s.supernodes(), 0);
  for (Eigen::Index i = 0; i < s.n; ++i) {
    if (!rhs.row(i).isZero(0.0)) {
      reached[static_cast<size_t>(s.supernode_of[static_cast<size_t>(s.position[static_cast<size_t>(i)])])] = 1;
    }
  }
  const ForwardSweep plan = plan_forward(l, s.sweeps.get(), executor, reached);
  const int64_t total = l.entries();
  auto sweep = [&](auto& x) {
    if (plan.two_threads) {
      s.sweeps->forward(l, x, *executor, plan.whole ? nullptr : &reached);
      return;
    }
    forward_sweep(l, x, reached);
  };
  Eigen::MatrixXd out(s.n, rhs.cols());
  if (rhs.cols() == 1) {  // Eigen's vector kernels
    Eigen::VectorXd x(s.n);
    for (Eigen::Index i = 0; i < s.n; ++i) x[s.position[static_cast<size_t>(i)]] = rhs(i, 0);
    sweep(x);
    out.col(0) = x;
  } else if (rhs.cols() > 1) {
    for (Eigen::Index i = 0; i < s.n; ++i) out.row(s.position[static_cast<size_t>(i)]) = rhs.row(i);
    sweep(out);
  }
  const int64_t work = plan.two_threads && plan.whole ? total : plan.work;
  if (fraction_read) *fraction_read = total > 0 ? static_cast<double>(work) / static_cast<double>(total) : 1.0;
  return out;
}

Eigen::MatrixXd CholeskyFactor::backward(const Eigen::MatrixXd& y, Executor* executor) const {
  const Symbolic& s = *state_->symbolic;
  const SupernodalLayout l = state_->layout();
  const bool two_threads = on_two_threads(s.sweeps.get(), executor);
  auto sweep = [&](auto& x) {
    if (two_threads) {
      s.sweeps->backward(l, x, *executor);
      return;
    }
    backward_sweep(l, x);
  };
  Eigen::MatrixXd out(y.rows(), y.cols());
  if (y.cols() == 1) {
    Eigen::VectorXd x = y.col(0);
    sweep(x);
    for (Eigen::Index i = 0; i < s.n; ++i) out(i, 0) = x[s.position[static_cast<size_t>(i)]];
  } else if (y.cols() > 1) {
    Eigen::MatrixXd x = y;
    sweep(x);
    for (Eigen::Index i = 0; i < s.n; ++i) out.row(i) = x.row(s.position[static_cast<size_t>(i)]);
  }
  return out;
}

}  // namespace softshell::engine::internal
