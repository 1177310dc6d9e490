// The GPL-free implementation of CholeskyFactor (SOFTSHELL_SPARSE_CHOLESKY=eigen): a simplicial
// L L^T in compressed columns, on Eigen's approximate-minimum-degree ordering. Only MPL-2.0 Eigen
// headers are used (EIGEN_MPL2_ONLY makes the compiler refuse any other); no BLAS, no SuiteSparse.
//
// The factorization is the up-looking one (row k of L is a sparse triangular solve with the
// rows above it, its pattern the elimination-tree reach of A's column k; as in T. Davis's LDL,
// which Eigen's SimplicialLLT also follows). It is written here rather than taken from
// SimplicialLLT because the engine needs what that class does not give: the symbolic analysis
// shared between factors of one pattern, the first failing column, the forward and backward
// sweeps separately, and the forward sweep restricted to the reach of local right-hand sides.
#ifndef EIGEN_MPL2_ONLY
#define EIGEN_MPL2_ONLY
#endif
#include "cholesky_factor.h"

#include <cmath>
#include <limits>
#include <new>
#include <vector>

#include <Eigen/OrderingMethods>

namespace softshell::engine::internal {
namespace {

using RowMajorMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Everything that depends on A's pattern only; shared by every factor of that pattern.
struct Symbolic {
  Eigen::Index n = 0;
  Eigen::Index a_nonzeros = 0;      // of the upper triangle given to factorize()
  std::vector<int32_t> position;    // position[i]: where row i of A is in the factor (P)
  std::vector<int32_t> original;    // original[k]: the row of A at factor position k (P^T)
  std::vector<int32_t> parent;      // elimination tree of P A P^T (-1: a root)
  // P A P^T's upper triangle by columns: row `c_row[q]`, value A.valuePtr()[c_value[q]].
  std::vector<int64_t> c_start;
  std::vector<int32_t> c_row, c_value;
  // L's pattern: column j is l_row[l_start[j] .. l_start[j + 1]), the diagonal first, then the
  // rows below it in ascending order.
  std::vector<int64_t> l_start;
  std::vector<int32_t> l_row;

  size_t bytes() const {
    return (position.size() + original.size() + parent.size() + c_row.size() + c_value.size() + l_row.size()) *
               sizeof(int32_t) +
           (c_start.size() + l_start.size()) * sizeof(int64_t);
  }
};

std::shared_ptr<const Symbolic> analyze(const Eigen::SparseMatrix<double>& upper) {
  auto s = std::make_shared<Symbolic>();
  const Eigen::Index n = upper.rows();
  s->n = n;
  s->a_nonzeros = upper.nonZeros();
  const auto un = static_cast<size_t>(n);

  // Fill-reducing ordering: AMD on the symmetric pattern (Eigen's returns P^T).
  Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> order;
  Eigen::AMDOrdering<int>()(upper.selfadjointView<Eigen::Upper>(), order);
  s->original.assign(order.indices().data(), order.indices().data() + n);
  s->position.assign(un, 0);
  for (Eigen::Index k = 0; k < n; ++k) s->position[static_cast<size_t>(s->original[static_cast<size_t>(k)])] = static_cast<int32_t>(k);

  // The upper triangle of P A P^T, each entry pointing at its value in A.
  std::vector<int64_t> count(un + 1, 0);
  for (Eigen::Index j = 0; j < n; ++j) {
    for (int p = upper.outerIndexPtr()[j]; p < upper.outerIndexPtr()[j + 1]; ++p) {
      const Eigen::Index i = upper.innerIndexPtr()[p];
      if (i > j) continue;
      const int32_t pi = s->position[static_cast<size_t>(i)], pj = s->position[static_cast<size_t>(j)];
      ++count[static_cast<size_t>(std::max(pi, pj)) + 1];
    }
  }
  for (size_t k = 0; k < un; ++k) count[k + 1] += count[k];
  s->c_start = count;
  s->c_row.resize(static_cast<size_t>(count[un]));
  s->c_value.resize(static_cast<size_t>(count[un]));
  for (Eigen::Index j = 0; j < n; ++j) {
    for (int p = upper.outerIndexPtr()[j]; p < upper.outerIndexPtr()[j + 1]; ++p) {
      const Eigen::Index i = upper.innerIndexPtr()[p];
      if (i > j) continue;
      const int32_t pi = s->position[static_cast<size_t>(i)], pj = s->position[static_cast<size_t>(j)];
      const auto q = static_cast<size_t>(count[static_cast<size_t>(std::max(pi, pj))]++);
      s->c_row[q] = std::min(pi, pj);
      s->c_value[q] = p;
    }
  }

  // Elimination tree and column counts: row k of L is the set of nodes on the tree paths from
  // the rows of C's column k up to k (Liu's algorithm, as in LDL).
  s->parent.assign(un, -1);
  std::vector<int32_t> tag(un, -1), below(un, 0);
  for (int32_t k = 0; k < n; ++k) {
    tag[static_cast<size_t>(k)] = k;
    for (int64_t q = s->c_start[static_cast<size_t>(k)]; q < s->c_start[static_cast<size_t>(k) + 1]; ++q) {
      for (int32_t i = s->c_row[static_cast<size_t>(q)]; tag[static_cast<size_t>(i)] != k; i = s->parent[static_cast<size_t>(i)]) {
        if (s->parent[static_cast<size_t>(i)] == -1) s->parent[static_cast<size_t>(i)] = k;
        ++below[static_cast<size_t>(i)];
        tag[static_cast<size_t>(i)] = k;
      }
    }
  }
  s->l_start.assign(un + 1, 0);
  for (size_t j = 0; j < un; ++j) s->l_start[j + 1] = s->l_start[j] + 1 + below[j];
  // The row indices: the same walk again, row k appended to each column it reaches.
  s->l_row.resize(static_cast<size_t>(s->l_start[un]));
  std::vector<int64_t> next(s->l_start.begin(), s->l_start.end() - 1);
  std::fill(tag.begin(), tag.end(), -1);
  for (int32_t k = 0; k < n; ++k) {
    tag[static_cast<size_t>(k)] = k;
    s->l_row[static_cast<size_t>(next[static_cast<size_t>(k)]++)] = k;  // the diagonal
    for (int64_t q = s->c_start[static_cast<size_t>(k)]; q < s->c_start[static_cast<size_t>(k) + 1]; ++q) {
      for (int32_t i = s->c_row[static_cast<size_t>(q)]; tag[static_cast<size_t>(i)] != k; i = s->parent[static_cast<size_t>(i)]) {
        s->l_row[static_cast<size_t>(next[static_cast<size_t>(i)]++)] = k;
        tag[static_cast<size_t>(i)] = k;
      }
    }
  }
  return s;
}

}  // namespace

struct CholeskyFactor::State {
  std::shared_ptr<const Symbolic> symbolic;
  std::vector<double> l_value;  // L's values, in the symbolic pattern's order
  double min_pivot = 0.0;
};

CholeskyFactor::CholeskyFactor(std::unique_ptr<State> state) : state_(std::move(state)) {}
CholeskyFactor::~CholeskyFactor() = default;

const char* CholeskyFactor::backend() { return "simplicial LL^T on Eigen's AMD (GPL-free)"; }

std::unique_ptr<CholeskyFactor> CholeskyFactor::factorize(const Eigen::SparseMatrix<double>& upper,
                                                          const CholeskyFactor* same_pattern, Failure& failure) {
  failure = Failure{};
  try {
    auto state = std::make_unique<State>();
    const Symbolic* known = same_pattern ? same_pattern->state_->symbolic.get() : nullptr;
    state->symbolic = known && known->n == upper.rows() && known->a_nonzeros == upper.nonZeros()
                          ? same_pattern->state_->symbolic
                          : analyze(upper);
    const Symbolic& s = *state->symbolic;
    const auto n = static_cast<size_t>(s.n);
    state->l_value.resize(s.l_row.size());
    double* lx = state->l_value.data();
    const int64_t* lp = s.l_start.data();
    const int32_t* li = s.l_row.data();
    const double* ax = upper.valuePtr();

    // Up-looking: row k of L solves L(0:k-1, 0:k-1) l = C(0:k-1, k) on the pattern found by
    // walking the tree from C's rows (in topological order: children before parents).
    std::vector<double> y(n, 0.0);
    std::vector<int32_t> pattern(n), tag(n, -1);
    std::vector<int64_t> next(n);  // next free slot of each column of L
    double low = std::numeric_limits<double>::infinity();
    for (int32_t k = 0; k < static_cast<int32_t>(n); ++k) {
      const auto uk = static_cast<size_t>(k);
      size_t top = n;
      tag[uk] = k;
      for (int64_t q = s.c_start[uk]; q < s.c_start[uk + 1]; ++q) {
        int32_t i = s.c_row[static_cast<size_t>(q)];
        y[static_cast<size_t>(i)] += ax[s.c_value[static_cast<size_t>(q)]];
        size_t len = 0;
        for (; tag[static_cast<size_t>(i)] != k; i = s.parent[static_cast<size_t>(i)]) {
          pattern[len++] = i;
          tag[static_cast<size_t>(i)] = k;
        }
        while (len > 0) pattern[--top] = pattern[--len];
      }
      double d = y[uk];
      y[uk] = 0.0;
      for (; top < n; ++top) {
        const auto i = static_cast<size_t>(pattern[top]);
        const double l_ki = y[i] / lx[lp[i]];
        y[i] = 0.0;
        const int64_t end = next[i];
        for (int64_t p = lp[i] + 1; p < end; ++p) y[static_cast<size_t>(li[p])] -= lx[p] * l_ki;
        d -= l_ki * l_ki;
        lx[end] = l_ki;  // li[end] == k: the symbolic walk visited the same nodes in this order
        next[i] = end + 1;
      }
      if (!(d > 0.0) || !std::isfinite(d)) {
        failure.column = s.original[uk];
        return nullptr;
      }
      lx[lp[uk]] = std::sqrt(d);
      next[uk] = lp[uk] + 1;
      low = std::min(low, d);
    }
    state->min_pivot = low;
    return std::unique_ptr<CholeskyFactor>(new CholeskyFactor(std::move(state)));
  } catch (const std::bad_alloc&) {
    failure.out_of_memory = true;
    return nullptr;
  }
}

Eigen::Index CholeskyFactor::size() const { return state_->symbolic->n; }

size_t CholeskyFactor::bytes() const {
  return state_->symbolic->bytes() + state_->l_value.size() * sizeof(double) + sizeof(State) + sizeof(Symbolic);
}

double CholeskyFactor::min_pivot() const { return state_->min_pivot; }

Eigen::MatrixXd CholeskyFactor::forward(const Eigen::MatrixXd& rhs, double* fraction_read) const {
  const Symbolic& s = *state_->symbolic;
  const auto n = static_cast<size_t>(s.n);
  const Eigen::Index m = rhs.cols();
  const double* lx = state_->l_value.data();
  const int64_t* lp = s.l_start.data();
  const int32_t* li = s.l_row.data();

  // P B, one contiguous row per factor row; the columns its nonzero rows reach (each with its
  // path to the root of the elimination tree).
  RowMajorMatrix x(s.n, m);
  std::vector<char> reached(n, 0);
  for (size_t i = 0; i < n; ++i) {
    const auto k = static_cast<size_t>(s.position[i]);
    x.row(static_cast<Eigen::Index>(k)) = rhs.row(static_cast<Eigen::Index>(i));
    if (x.row(static_cast<Eigen::Index>(k)).isZero(0.0)) continue;
    for (int32_t j = static_cast<int32_t>(k); j >= 0 && !reached[static_cast<size_t>(j)]; j = s.parent[static_cast<size_t>(j)]) {
      reached[static_cast<size_t>(j)] = 1;
    }
  }
  int64_t work = 0;
  double* xv = x.data();
  for (size_t j = 0; j < n; ++j) {
    if (!reached[j]) continue;
    const int64_t begin = lp[j], end = lp[j + 1];
    work += end - begin;
    double* xj = xv + static_cast<Eigen::Index>(j) * m;
    const double inverse = 1.0 / lx[begin];
    for (Eigen::Index c = 0; c < m; ++c) xj[c] *= inverse;
    for (int64_t p = begin + 1; p < end; ++p) {
      double* xi = xv + static_cast<Eigen::Index>(li[p]) * m;
      const double l = lx[p];
      for (Eigen::Index c = 0; c < m; ++c) xi[c] -= l * xj[c];
    }
  }
  if (fraction_read) *fraction_read = lp[n] > 0 ? static_cast<double>(work) / static_cast<double>(lp[n]) : 1.0;
  return x;
}

Eigen::MatrixXd CholeskyFactor::backward(const Eigen::MatrixXd& y) const {
  const Symbolic& s = *state_->symbolic;
  const auto n = static_cast<size_t>(s.n);
  const Eigen::Index m = y.cols();
  const double* lx = state_->l_value.data();
  const int64_t* lp = s.l_start.data();
  const int32_t* li = s.l_row.data();
  RowMajorMatrix x = y;
  double* xv = x.data();
  for (size_t j = n; j-- > 0;) {
    double* xj = xv + static_cast<Eigen::Index>(j) * m;
    for (int64_t p = lp[j] + 1; p < lp[j + 1]; ++p) {
      const double* xi = xv + static_cast<Eigen::Index>(li[p]) * m;
      const double l = lx[p];
      for (Eigen::Index c = 0; c < m; ++c) xj[c] -= l * xi[c];
    }
    const double inverse = 1.0 / lx[lp[j]];
    for (Eigen::Index c = 0; c < m; ++c) xj[c] *= inverse;
  }
  Eigen::MatrixXd out(y.rows(), m);
  for (size_t i = 0; i < n; ++i) out.row(static_cast<Eigen::Index>(i)) = x.row(s.position[i]);
  return out;
}

}  // namespace softshell::engine::internal
