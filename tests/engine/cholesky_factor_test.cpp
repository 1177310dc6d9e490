// The sparse Cholesky backend this build was configured with (SOFTSHELL_SPARSE_CHOLESKY: CHOLMOD
// or the GPL-free supernodal one) against a dense Eigen LLT: solves, the split into forward and
// backward sweeps, local right-hand sides, reuse of a symbolic analysis, and matrices that are not
// positive definite, which must be reported (the solver's zero-mode and consistency handling rely
// on it), never answered with NaNs. Run in each backend's build, the same assertions hold both to
// the same reference.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <tuple>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SparseCholesky>

#include "cholesky_factor.h"
#include "factorization.h"
#include "scoped_knob.h"
#include "softshell/executor.h"
#include "supernodal_numeric.h"
#include "supernodal_sweeps.h"

namespace softshell::engine::internal {
namespace {

using test::ScopedKnob;

using Sparse = Eigen::SparseMatrix<double>;

Sparse upper_of(const Sparse& a) {
  Sparse u = a.triangularView<Eigen::Upper>();
  u.makeCompressed();
  return u;
}

// A graph Laplacian on a 2D grid (nx x ny nodes): node (i, j) couples with (i + di, j + dj) by
// weight w for each {di, dj, w} of `stencil` inside the grid; plus `shift` on the diagonal.
struct Coupling {
  int di, dj;
  double w;
};
Sparse grid_graph(int nx, int ny, const std::vector<Coupling>& stencil, double shift) {
  std::vector<Eigen::Triplet<double>> t;
  auto id = [&](int i, int j) { return j * nx + i; };
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      double degree = 0.0;
      for (const auto& [di, dj, w] : stencil) {
        const int i2 = i + di, j2 = j + dj;
        if (i2 < 0 || i2 >= nx || j2 < 0 || j2 >= ny) continue;
        t.emplace_back(id(i, j), id(i2, j2), -w);
        degree += w;
      }
      t.emplace_back(id(i, j), id(i, j), degree + shift);
    }
  }
  Sparse a(nx * ny, nx * ny);
  a.setFromTriplets(t.begin(), t.end());
  return a;
}

// A 2D grid Laplacian (nx x ny nodes, 5-point) plus `shift` on the diagonal.
Sparse grid_laplacian(int nx, int ny, double shift) {
  return grid_graph(nx, ny, {{1, 0, 1.0}, {-1, 0, 1.0}, {0, 1, 1.0}, {0, -1, 1.0}}, shift);
}

// A grid whose nodes couple with every node within `radius` steps in each direction (as control
// points of a subdivision surface do): wider separators, so larger dense blocks in the factor.
Sparse wide_grid(int nx, int ny, int radius) {
  std::vector<Coupling> stencil;
  for (int dj = -radius; dj <= radius; ++dj) {
    for (int di = -radius; di <= radius; ++di) {
      if (di != 0 || dj != 0) stencil.push_back({di, dj, 1.0 / (std::abs(di) + std::abs(dj))});
    }
  }
  return grid_graph(nx, ny, stencil, 0.05);
}

// kron(graph, block): three coupled DOFs per node, as in the shell's stiffness; every node's
// three columns share one structure, so the factor has supernodes of at least three columns.
Sparse with_blocks(const Sparse& graph, const Eigen::Matrix3d& block) {
  std::vector<Eigen::Triplet<double>> t;
  for (Eigen::Index j = 0; j < graph.outerSize(); ++j) {
    for (Sparse::InnerIterator it(graph, j); it; ++it) {
      for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) {
          const double v = it.row() == it.col() ? it.value() * block(a, b) : it.value() * (a == b ? 1.0 : 0.1);
          t.emplace_back(3 * static_cast<int>(it.row()) + a, 3 * static_cast<int>(it.col()) + b, v);
        }
      }
    }
  }
  Sparse a(3 * graph.rows(), 3 * graph.cols());
  a.setFromTriplets(t.begin(), t.end());
  return a;
}

// The 3 x 3 block the tests couple each node's DOFs with (symmetric positive definite).
Eigen::Matrix3d node_block() {
  Eigen::Matrix3d block;
  block << 2.0, 0.3, -0.2, 0.3, 1.5, 0.1, -0.2, 0.1, 1.8;
  return block;
}

// An arrow matrix: a tridiagonal chain plus a dense last row and column (a wide root supernode).
Sparse arrow(int n) {
  std::vector<Eigen::Triplet<double>> t;
  for (int i = 0; i < n; ++i) {
    t.emplace_back(i, i, 4.0 + 0.01 * i);
    if (i + 1 < n - 1) {
      t.emplace_back(i, i + 1, -1.0);
      t.emplace_back(i + 1, i, -1.0);
    }
    if (i < n - 1) {
      t.emplace_back(i, n - 1, 0.05);
      t.emplace_back(n - 1, i, 0.05);
    }
  }
  Sparse a(n, n);
  a.setFromTriplets(t.begin(), t.end());
  return a;
}

// A dense SPD matrix (as a sparse one): one supernode, large enough for Eigen's blocked LLT.
Sparse dense_spd(int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::MatrixXd m(n, n);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) m(i, j) = u(rng);
  }
  const Eigen::MatrixXd a = m * m.transpose() + n * Eigen::MatrixXd::Identity(n, n);
  return a.sparseView();
}

// The same pattern with the diagonal times `factor` (a tangent stiffness beside K; negative: indefinite).
Sparse with_scaled_diagonal(Sparse a, double factor) {
  for (Eigen::Index j = 0; j < a.outerSize(); ++j) {
    for (Sparse::InnerIterator it(a, j); it; ++it) {
      if (it.row() == it.col()) it.valueRef() *= factor;
    }
  }
  return a;
}

Eigen::MatrixXd random_rhs(Eigen::Index rows, Eigen::Index cols, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::MatrixXd b(rows, cols);
  for (Eigen::Index j = 0; j < cols; ++j) {
    for (Eigen::Index i = 0; i < rows; ++i) b(i, j) = u(rng);
  }
  return b;
}

double relative_error(const Eigen::MatrixXd& x, const Eigen::MatrixXd& reference) {
  return (x - reference).norm() / reference.norm();
}

std::unique_ptr<CholeskyFactor> factor_of(const Sparse& a, const CholeskyFactor* same_pattern = nullptr) {
  CholeskyFactor::Failure failure;
  auto f = CholeskyFactor::factorize(upper_of(a), same_pattern, failure);
  EXPECT_TRUE(f) << "failed at column " << failure.column;
  return f;
}

// Solves, the sweep identities and the pivots against the dense factorization of `a`.
void expect_matches_dense(const Sparse& a, const char* what) {
  SCOPED_TRACE(what);
  const auto f = factor_of(a);
  ASSERT_TRUE(f);
  ASSERT_EQ(f->size(), a.rows());
  const Eigen::MatrixXd dense = a;
  const Eigen::LLT<Eigen::MatrixXd> llt(dense);
  ASSERT_EQ(llt.info(), Eigen::Success);
  // Condition numbers here are below 1e4: 1e-11 is round-off, not a loose tolerance.
  for (Eigen::Index cols : {1, 4}) {
    const Eigen::MatrixXd b = random_rhs(a.rows(), cols, 7u + static_cast<unsigned>(cols));
    const Eigen::MatrixXd y = f->forward(b);
    EXPECT_TRUE(y.allFinite());
    EXPECT_LT(relative_error(f->backward(y), llt.solve(b)), 1e-11) << cols << " right-hand sides";
    // forward(B)^T forward(B) = B^T A^-1 B, whatever the ordering.
    EXPECT_LT(relative_error(y.transpose() * y, b.transpose() * llt.solve(b)), 1e-11);
  }
  // min L_kk^2: positive, and at most A's smallest diagonal entry (L_kk^2 <= A_kk in any order).
  EXPECT_GT(f->min_pivot(), 0.0);
  EXPECT_LE(f->min_pivot(), dense.diagonal().minCoeff() * (1.0 + 1e-12));
  EXPECT_GT(f->bytes(), 0u);
}

TEST(CholeskyFactor, BackendIsNamed) {
  ASSERT_NE(CholeskyFactor::backend(), nullptr);
  EXPECT_GT(std::string(CholeskyFactor::backend()).size(), 0u);
  RecordProperty("backend", CholeskyFactor::backend());
}

TEST(CholeskyFactor, MatchesDenseLltOnSmallSpdMatrices) {
  Sparse one(1, 1);
  one.insert(0, 0) = 2.5;
  expect_matches_dense(one, "1 x 1");
  Sparse diagonal(5, 5);
  for (int i = 0; i < 5; ++i) diagonal.insert(i, i) = 1.0 + i;
  expect_matches_dense(diagonal, "diagonal");
  expect_matches_dense(grid_laplacian(9, 7, 0.1), "grid Laplacian");
  const Eigen::Matrix3d block = node_block();
  expect_matches_dense(with_blocks(grid_laplacian(8, 6, 0.2), block), "3 DOFs per node (supernodes)");
  expect_matches_dense(arrow(60), "arrow (dense root)");
  expect_matches_dense(dense_spd(150, 3), "dense 150 x 150 (one supernode, blocked LLT)");
}

TEST(CholeskyFactor, LocalRightHandSideSweepsPartOfTheFactor) {
  const Eigen::Matrix3d block = node_block();
  const Sparse a = with_blocks(grid_laplacian(30, 30, 0.05), block);
  const auto f = factor_of(a);
  ASSERT_TRUE(f);
  Eigen::MatrixXd b = Eigen::MatrixXd::Zero(a.rows(), 2);
  b(3 * 17 + 1, 0) = 1.0;  // one node near a corner: few elimination-tree paths
  b(3 * 17 + 2, 1) = -0.5;
  b(3 * 18, 1) = 2.0;
  double fraction = 0.0;
  const Eigen::MatrixXd y = f->forward(b, &fraction);
  EXPECT_GT(fraction, 0.0);
  RecordProperty("fraction_read", std::to_string(fraction));
  EXPECT_LT(fraction, 0.5);  // a nested-dissection-like ordering of a grid: a local load reaches a small share
  // Large enough for CHOLMOD to choose its supernodal factor: the reference is Eigen's sparse
  // simplicial LLT rather than a dense one.
  const Eigen::SimplicialLLT<Sparse> reference(a);
  ASSERT_EQ(reference.info(), Eigen::Success);
  const Eigen::MatrixXd x = reference.solve(b);
  EXPECT_LT(relative_error(f->backward(y), x), 1e-11);
  EXPECT_LT(relative_error(y.transpose() * y, b.transpose() * x), 1e-11);
}

TEST(CholeskyFactor, ReusesTheAnalysisForAnotherMatrixOfThePattern) {
  const Eigen::Matrix3d block = node_block();
  const Sparse a = with_blocks(grid_laplacian(10, 8, 0.2), block);
  const Sparse a2 = with_scaled_diagonal(a, 1.5);  // same pattern, other values
  const auto first = factor_of(a);
  ASSERT_TRUE(first);
  const auto second = factor_of(a2, first.get());
  ASSERT_TRUE(second);
  const Eigen::MatrixXd b = random_rhs(a.rows(), 3, 11);
  const Eigen::MatrixXd dense2 = a2;
  EXPECT_LT(relative_error(second->backward(second->forward(b)), Eigen::LLT<Eigen::MatrixXd>(dense2).solve(b)), 1e-11);
  const Eigen::MatrixXd dense = a;  // and the first factor is untouched
  EXPECT_LT(relative_error(first->backward(first->forward(b)), Eigen::LLT<Eigen::MatrixXd>(dense).solve(b)), 1e-11);
}

// A factor that is let go of is refactored in place by the next factorization of its analysis
// (the CHOLMOD build keeps two large ones; here any size), also after a failed one left it: each
// answer as from scratch.
TEST(CholeskyFactor, RefactorsIntoAFactorLetGo) {
  const ScopedKnob<size_t> keep_any_size(g_spare_factor_bytes, 0);
  const Eigen::Matrix3d block = node_block();
  const Sparse a = with_blocks(grid_laplacian(30, 30, 0.05), block);  // large enough to be supernodal
  const Sparse stiffer = with_scaled_diagonal(a, 1.5), indefinite = with_scaled_diagonal(a, -1.0);
  const Eigen::MatrixXd b = random_rhs(a.rows(), 2, 5);
  auto expect_solves = [&](const CholeskyFactor& f, const Sparse& m, const char* what) {
    const Eigen::SimplicialLLT<Sparse> reference(m);
    ASSERT_EQ(reference.info(), Eigen::Success);
    EXPECT_LT(relative_error(f.backward(f.forward(b)), reference.solve(b)), 1e-11) << what;
  };
  const auto first = factor_of(a);
  ASSERT_TRUE(first);
  for (int round = 0; round < 3; ++round) {
    { const auto let_go = factor_of(stiffer, first.get()); }
    CholeskyFactor::Failure failure;
    EXPECT_FALSE(CholeskyFactor::factorize(upper_of(indefinite), first.get(), failure));
    EXPECT_GE(failure.column, 0);
    const auto again = factor_of(stiffer, first.get());
    ASSERT_TRUE(again);
    expect_solves(*again, stiffer, "refactored after a failure");
  }
  expect_solves(*first, a, "the first factor, untouched");
}

// Whole sweeps on two threads (supernodal_sweeps.h): the same solves as on one, to round-off, for
// one and several right-hand sides, with a dense and a local right-hand side, and on an executor
// of one thread (which sweeps alone). Any factor size is planned here; the default leaves factors
// under 8 MB to one thread.
TEST(CholeskyFactor, SweepsOnTwoThreadsSolveAsOnOne) {
  const ScopedKnob<int64_t> plan_any_size(g_two_thread_sweep_entries, 0);
  const Eigen::Matrix3d block = node_block();
  const Sparse a = with_blocks(grid_laplacian(40, 36, 0.05), block);  // supernodal in both backends
  const auto f = factor_of(a);
  ASSERT_TRUE(f);
  ASSERT_TRUE(f->two_thread_sweeps()) << "a grid's elimination tree splits into two halves";
  ThreadPool pool(2);
  InlineExecutor alone;
  const Eigen::SimplicialLLT<Sparse> reference(a);
  ASSERT_EQ(reference.info(), Eigen::Success);
  for (Eigen::Index cols : {1, 3}) {
    SCOPED_TRACE(cols);
    const Eigen::MatrixXd b = random_rhs(a.rows(), cols, 13u + static_cast<unsigned>(cols));
    double fraction = 0.0;
    const Eigen::MatrixXd y1 = f->forward(b), y2 = f->forward(b, &fraction, &pool);
    EXPECT_EQ(fraction, 1.0);
    EXPECT_LT(relative_error(y2, y1), 1e-13);
    const Eigen::MatrixXd x2 = f->backward(y2, &pool);
    EXPECT_LT(relative_error(x2, f->backward(y1)), 1e-13);
    EXPECT_LT(relative_error(x2, reference.solve(b)), 1e-11);
    EXPECT_LT(relative_error(f->backward(f->forward(b, nullptr, &alone), &alone), reference.solve(b)), 1e-11);
    // Many solves at once on the pool's threads (the service's case): each its own answer.
    std::vector<Eigen::MatrixXd> answers(6);
    pool.parallel_for(0, 6, [&](int64_t i) {
      answers[static_cast<size_t>(i)] = f->backward(f->forward((1.0 + static_cast<double>(i)) * b, nullptr, &pool), &pool);
    });
    for (size_t i = 0; i < answers.size(); ++i) {
      EXPECT_LT(relative_error(answers[i], (1.0 + static_cast<double>(i)) * x2), 1e-13) << "solve " << i;
    }
  }
  // A local right-hand side still sweeps only its part of the factor (here on two threads too: any
  // sweep is planned).
  Eigen::MatrixXd local = Eigen::MatrixXd::Zero(a.rows(), 1);
  local(3 * 17 + 1, 0) = 1.0;
  double fraction = 1.0;
  const Eigen::MatrixXd y = f->forward(local, &fraction, &pool);
  EXPECT_LT(fraction, 0.5);
  EXPECT_LT(relative_error(f->backward(y, &pool), reference.solve(local)), 1e-11);
}

// A factor whose sweeps read L rounded to single precision (the nonlinear solver's preconditioners):
// every sweep, of one column or several, on one thread or two, is one with the same rounded L~, so
// a solve is exact for A~ = L~ L~^T (the constrained solves on top of it rely on that), and A~ is
// within float's rounding of A. A matrix whose L would leave float's range keeps exact sweeps.
TEST(CholeskyFactor, SingleSweepsSolveWithTheRoundedFactor) {
  const ScopedKnob<int64_t> plan_any_size(g_two_thread_sweep_entries, 0);
  const Sparse a = with_blocks(grid_laplacian(40, 36, 0.05), node_block());  // supernodal in both backends
  ThreadPool pool(2);
  CholeskyFactor::Failure failure;
  const auto exact = factor_of(a);
  const auto single = CholeskyFactor::factorize(upper_of(a), nullptr, failure, &pool, SweepPrecision::kSingle);
  ASSERT_TRUE(exact && single);
  ASSERT_FALSE(exact->single_precision_sweeps());
  ASSERT_TRUE(single->single_precision_sweeps());
  ASSERT_TRUE(single->two_thread_sweeps());
  EXPECT_EQ(single->min_pivot(), exact->min_pivot()) << "the pivots are the factorization's own";
  EXPECT_GT(single->bytes(), exact->bytes());

  const Eigen::MatrixXd b = random_rhs(a.rows(), 3, 29u);
  const Eigen::MatrixXd x = exact->backward(exact->forward(b));
  // One column at a time (the single-precision kernels) and three at once (blocks widened to
  // double), on one thread and on two: the same operator to double round-off.
  const Eigen::MatrixXd y3 = single->forward(b), x3 = single->backward(y3);
  for (Executor* executor : {static_cast<Executor*>(nullptr), static_cast<Executor*>(&pool)}) {
    SCOPED_TRACE(executor ? "two threads" : "one thread");
    for (Eigen::Index c = 0; c < b.cols(); ++c) {
      const Eigen::MatrixXd y1 = single->forward(b.col(c), nullptr, executor);
      EXPECT_LT(relative_error(y1, y3.col(c)), 1e-13) << "forward, column " << c;
      EXPECT_LT(relative_error(single->backward(y1, executor), x3.col(c)), 1e-13) << "backward, column " << c;
      EXPECT_LT(relative_error(single->backward(y3.col(c), executor), x3.col(c)), 1e-13);
    }
  }
  // Forward and backward sweep the same L~: forward(B)^T forward(B) = B^T A~^-1 B.
  EXPECT_LT(relative_error(y3.transpose() * y3, b.transpose() * x3), 1e-13);
  // A~ is A to float's rounding: the solve is off by about that times the condition number (a few
  // hundred here), and not exact (the rounded L is in use).
  const double off = relative_error(x3, x);
  EXPECT_GT(off, 1e-12);
  EXPECT_LT(off, 1e-5);
  EXPECT_LT(relative_error(a * x3, b), 1e-5);

  // Scaled far out of float's range (L ~ 1e40): exact sweeps, not infinities.
  const Sparse huge = a * 1e80;
  const auto kept = CholeskyFactor::factorize(upper_of(huge), nullptr, failure, &pool, SweepPrecision::kSingle);
  ASSERT_TRUE(kept);
  EXPECT_FALSE(kept->single_precision_sweeps());
  EXPECT_LT(relative_error(kept->backward(kept->forward(b)), x * 1e-80), 1e-11);
}

// The numeric factorization on two threads (supernodal_numeric.h: both halves of the tree at once,
// then the top): the same factor bit for bit as on one thread, for a fresh analysis and a reused
// one, and the same refusal (the same column, the same finiteness) wherever the failing pivot lies,
// in a half or in the top.
TEST(CholeskyFactor, FactorsOnTwoThreadsBitForBitAsOnOne) {
  const ScopedKnob<int64_t> plan_any_size(g_two_thread_sweep_entries, 0);
  // Every update product of the top big enough to split goes to two threads (bands of rows).
  const ScopedKnob<double> share_any_size(g_shared_product_flops, 0.0);
  const Eigen::Matrix3d block = node_block();
  const int nx = 40, ny = 36;
  const Sparse a = with_blocks(grid_laplacian(nx, ny, 0.05), block);
  ThreadPool pool(2);
  auto factor = [&](const Sparse& m, const CholeskyFactor* same_pattern, bool two_threads,
                    CholeskyFactor::Failure& failure) {
    return CholeskyFactor::factorize(upper_of(m), same_pattern, failure, two_threads ? &pool : nullptr);
  };
  CholeskyFactor::Failure failure;
  const auto one = factor(a, nullptr, false, failure);
  const auto two = factor(a, nullptr, true, failure);
  ASSERT_TRUE(one && two);
  ASSERT_TRUE(two->two_thread_sweeps()) << "a grid's elimination tree splits into two halves";
  const Eigen::MatrixXd b = random_rhs(a.rows(), 2, 21);
  // Sweeps on one thread read every entry of L: equal answers, bit for bit, mean equal factors.
  EXPECT_TRUE(one->forward(b) == two->forward(b));
  EXPECT_TRUE(one->backward(b) == two->backward(b));
  EXPECT_LT(relative_error(two->backward(two->forward(b)), Eigen::SimplicialLLT<Sparse>(a).solve(b)), 1e-11);
  // Another matrix of the pattern, into the same analysis.
  const Sparse shifted = with_scaled_diagonal(a, 1.5);
  const auto one_again = factor(shifted, one.get(), false, failure);
  const auto two_again = factor(shifted, two.get(), true, failure);
  ASSERT_TRUE(one_again && two_again);
  EXPECT_TRUE(one_again->forward(b) == two_again->forward(b));
  {
    // Off: one thread even with the executor.
    const ScopedKnob<bool> off(g_two_thread_factorization, false);
    const auto alone = factor(a, nullptr, true, failure);
    ASSERT_TRUE(alone);
    EXPECT_TRUE(alone->forward(b) == one->forward(b));
  }
  {
    // Wider separators: top products to share (11 with CHOLMOD's ordering), of rows not multiples
    // of the register tile, and a root of 510 columns whose dense LLT is shared too. The
    // comparison fails if a shared product sums in another order (checked by splitting one, and
    // the LLT's second band's product, along its depth).
    const Sparse wide = with_blocks(wide_grid(60, 56, 2), block);
    const int64_t before = g_shared_products.load();
    const auto wide_one = factor(wide, nullptr, false, failure);
    const auto wide_two = factor(wide, nullptr, true, failure);
    ASSERT_TRUE(wide_one && wide_two);
    EXPECT_GT(g_shared_products.load() - before, 0) << "the top has products to share";
    const Eigen::MatrixXd bw = random_rhs(wide.rows(), 2, 22);
    EXPECT_TRUE(wide_one->forward(bw) == wide_two->forward(bw));
    EXPECT_LT(relative_error(wide_two->backward(wide_two->forward(bw)), Eigen::SimplicialLLT<Sparse>(wide).solve(bw)), 1e-10);
  }
  // Failing pivots along the middle column of nodes and off it: in this build's ordering the
  // first fails in the top of the split, the others in the halves (checked with a trace).
  int refused = 0;
  for (const auto& [i, j, nan] : {std::tuple{nx / 2, ny / 2, false}, std::tuple{nx / 2, 3, false},
                                  std::tuple{nx / 2 - 1, ny - 2, false}, std::tuple{3, 5, false},
                                  std::tuple{nx - 4, ny - 6, false}, std::tuple{7, ny / 2, true},
                                  std::tuple{nx - 2, 1, true}, std::tuple{nx / 2, ny / 3, true}}) {
    SCOPED_TRACE(testing::Message() << "node (" << i << ", " << j << ")" << (nan ? ", NaN" : ", negative"));
    Sparse bad = a;
    const int dof = 3 * (j * nx + i) + 1;
    bad.coeffRef(dof, dof) = nan ? std::numeric_limits<double>::quiet_NaN() : -1.0;
    CholeskyFactor::Failure on_one, on_two;
    EXPECT_FALSE(factor(bad, nullptr, false, on_one));
    EXPECT_FALSE(factor(bad, two.get(), true, on_two));
    EXPECT_EQ(on_two.column, on_one.column);
    EXPECT_EQ(on_two.not_finite, on_one.not_finite);
    EXPECT_EQ(on_one.not_finite, nan);
    refused += on_one.column >= 0;
  }
  EXPECT_EQ(refused, 8);
}

// A factor's layout by hand, one column per supernode: column k's rows below it are `below[k]`.
struct HandLayout {
  std::vector<int32_t> first, rows, supernode_of;
  std::vector<int64_t> row_start{0}, value_start{0};
  std::vector<double> values;
  explicit HandLayout(const std::vector<std::vector<int32_t>>& below) {
    for (size_t k = 0; k < below.size(); ++k) {
      first.push_back(static_cast<int32_t>(k));
      supernode_of.push_back(static_cast<int32_t>(k));
      rows.push_back(static_cast<int32_t>(k));
      rows.insert(rows.end(), below[k].begin(), below[k].end());
      row_start.push_back(static_cast<int64_t>(rows.size()));
      value_start.push_back(value_start.back() + static_cast<int64_t>(below[k].size() + 1));
    }
    first.push_back(static_cast<int32_t>(below.size()));
    values.assign(static_cast<size_t>(value_start.back()), 1.0);
  }
  SupernodalLayout view() const {
    return {static_cast<int64_t>(first.size()) - 1, first.data(), row_start.data(), value_start.data(),
            rows.data(), supernode_of.data(), values.data()};
  }
};

// The plan: two halves of whole subtrees and a small top where the tree branches; none for a
// chain (every split would move it all to the top) or a factor below the size threshold.
TEST(CholeskyFactor, TwoThreadPlanNeedsATreeThatSplits) {
  const ScopedKnob<int64_t> plan_any_size(g_two_thread_sweep_entries, 0);
  // Two chains of 50 columns joined by a root: 0..49 -> 100, 50..99 -> 100.
  std::vector<std::vector<int32_t>> branches(101);
  for (int32_t k = 0; k < 100; ++k) branches[static_cast<size_t>(k)] = {k % 50 == 49 ? 100 : k + 1, 100};
  branches[49] = {100};
  branches[99] = {100};
  const HandLayout two(branches);
  const auto plan = TwoThreadSweeps::plan(two.view());
  ASSERT_TRUE(plan);
  EXPECT_LT(plan->top_share(), 0.01);  // the root alone
  std::vector<std::vector<int32_t>> line(100);
  for (int32_t k = 0; k + 1 < 100; ++k) line[static_cast<size_t>(k)] = {k + 1};
  const HandLayout chain(line);
  EXPECT_FALSE(TwoThreadSweeps::plan(chain.view()));
  g_two_thread_sweep_entries.store(two.view().entries() + 1);
  EXPECT_FALSE(TwoThreadSweeps::plan(two.view())) << "below the threshold";
}

// Expects factorize() to refuse `a`, name a column in range and say whether A held non-finite
// values.
void expect_refused(const Sparse& a, const char* what, bool not_finite = false, Eigen::Index expected_column = -1) {
  SCOPED_TRACE(what);
  CholeskyFactor::Failure failure;
  const auto f = CholeskyFactor::factorize(upper_of(a), nullptr, failure);
  EXPECT_FALSE(f);
  EXPECT_FALSE(failure.out_of_memory);
  EXPECT_EQ(failure.not_finite, not_finite);
  EXPECT_GE(failure.column, 0);
  EXPECT_LT(failure.column, a.rows());
  if (expected_column >= 0) {
    EXPECT_EQ(failure.column, expected_column);
  }
}

// Large matrices are ordered differently (CHOLMOD: nested dissection beside AMD, from 6,000 rows):
// matrices on both sides of that size stay exact, in either order on one thread (whose settings
// the last factorization left), and an indefinite large matrix is still refused.
TEST(CholeskyFactor, LargeAndSmallMatricesAreBothExact) {
  const Eigen::Matrix3d block = node_block();
  const Sparse large = with_blocks(grid_laplacian(48, 48, 0.05), block);  // 6,912 rows
  const Sparse small = with_blocks(grid_laplacian(10, 8, 0.2), block);
  ASSERT_GE(large.rows(), 6000);
  for (const Sparse* a : {&small, &large, &small}) {
    SCOPED_TRACE(a->rows());
    const auto f = factor_of(*a);
    ASSERT_TRUE(f);
    const Eigen::MatrixXd b = random_rhs(a->rows(), 2, 5);
    const Eigen::SimplicialLLT<Sparse> reference(*a);
    ASSERT_EQ(reference.info(), Eigen::Success);
    EXPECT_LT(relative_error(f->backward(f->forward(b)), reference.solve(b)), 1e-11);
  }
  Sparse indefinite = large;
  indefinite.coeffRef(4000, 4000) = -1.0;
  expect_refused(indefinite, "large, one negative diagonal entry");
}

TEST(CholeskyFactor, ReportsMatricesThatAreNotPositiveDefinite) {
  Sparse diagonal(6, 6);
  for (int i = 0; i < 6; ++i) diagonal.insert(i, i) = i == 4 ? -1.0 : 1.0 + i;
  expect_refused(diagonal, "one negative diagonal entry", false, 4);
  // A grid Laplacian shifted below zero: smallest eigenvalue -0.05, every diagonal entry positive.
  expect_refused(grid_laplacian(9, 7, -0.05), "indefinite grid Laplacian");
  const Eigen::Matrix3d block = node_block();
  Sparse blocks = with_blocks(grid_laplacian(8, 6, 0.2), block);
  // One node's 3x3 block made indefinite (eigenvalues 3 and -1 in the first two DOFs).
  blocks.coeffRef(3 * 20, 3 * 20) = 1.0;
  blocks.coeffRef(3 * 20 + 1, 3 * 20 + 1) = 1.0;
  blocks.coeffRef(3 * 20, 3 * 20 + 1) = 2.0;
  blocks.coeffRef(3 * 20 + 1, 3 * 20) = 2.0;
  expect_refused(blocks, "an indefinite block inside a supernode");
  // A dense matrix whose failing pivot lies past Eigen's first LLT block.
  Sparse dense = dense_spd(150, 5);
  Eigen::MatrixXd d = dense;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(d);
  const Eigen::VectorXd v = eig.eigenvectors().col(0);
  d -= (eig.eigenvalues()[0] + 1.0) * v * v.transpose();  // smallest eigenvalue now -1
  expect_refused(d.sparseView(), "dense, one negative eigenvalue");
  // Non-finite input is refused, not propagated.
  Sparse nan = grid_laplacian(5, 5, 0.1);
  nan.coeffRef(7, 7) = std::numeric_limits<double>::quiet_NaN();
  expect_refused(nan, "NaN on the diagonal", true);
  Sparse nan_off = grid_laplacian(5, 5, 0.1);
  nan_off.coeffRef(7, 8) = nan_off.coeffRef(8, 7) = std::numeric_limits<double>::quiet_NaN();
  expect_refused(nan_off, "NaN off the diagonal", true);
}

// The numeric factorization's kernels (supernodal_numeric.h) are built twice, for the baseline and
// for x86-64-v3, and the second runs where the CPU has it. Both factor exactly (against dense and
// sparse references), refuse what is not positive definite or finite, and agree with each other
// to round-off (they differ only in the order of their sums).
TEST(CholeskyFactor, BothKernelBuildsFactorAlike) {
  RecordProperty("kernels", supernodal_kernels());
  const Eigen::Matrix3d block = node_block();
  const Sparse a = with_blocks(grid_laplacian(30, 30, 0.05), block);  // large enough to be supernodal
  const Eigen::MatrixXd b = random_rhs(a.rows(), 2, 9);
  const auto fast = factor_of(a);
  ASSERT_TRUE(fast);
  const ScopedKnob<bool> baseline(g_supernodal_baseline_kernels, true);
  EXPECT_STREQ(supernodal_kernels(), "baseline");
  const auto slow = factor_of(a);
  ASSERT_TRUE(slow);
  EXPECT_LT(relative_error(slow->forward(b), fast->forward(b)), 1e-13);
  const Eigen::SimplicialLLT<Sparse> reference(a);
  ASSERT_EQ(reference.info(), Eigen::Success);
  EXPECT_LT(relative_error(slow->backward(slow->forward(b)), reference.solve(b)), 1e-11);
  expect_matches_dense(with_blocks(grid_laplacian(8, 6, 0.2), block), "baseline kernels, 3 DOFs per node");
  expect_matches_dense(dense_spd(150, 3), "baseline kernels, dense 150 x 150");
  Sparse indefinite = a;
  indefinite.coeffRef(1000, 1000) = -1.0;
  expect_refused(indefinite, "baseline kernels, one negative diagonal entry", false, 1000);
  Sparse nan = a;
  nan.coeffRef(1500, 1501) = nan.coeffRef(1501, 1500) = std::numeric_limits<double>::quiet_NaN();
  expect_refused(nan, "baseline kernels, NaN off the diagonal", true);
}

// The engine's wrappers: SparseCholesky says !ok(); Factorization throws FactorizationFailed
// naming the control point and axis of the failing pivot.
TEST(CholeskyFactor, WrappersReportIndefiniteMatrices) {
  Sparse diagonal(9, 9);
  for (int i = 0; i < 9; ++i) diagonal.insert(i, i) = i == 5 ? -2.0 : 1.0;
  const SparseCholesky zero_modes(diagonal);
  EXPECT_FALSE(zero_modes.ok());
  EXPECT_EQ(zero_modes.min_pivot(), 0.0);
  const SparseCholesky fine(grid_laplacian(4, 4, 0.5));
  ASSERT_TRUE(fine.ok());
  EXPECT_GT(fine.min_pivot(), 0.0);
  try {
    const Factorization f(diagonal, {0}, {});  // DOF 5 is factor column 4
    FAIL() << "an indefinite matrix was factorized";
  } catch (const FactorizationFailed& e) {
    EXPECT_NE(std::string(e.what()).find("not positive definite"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("control point 1, axis z"), std::string::npos) << e.what();
  }
  Sparse nan = grid_laplacian(4, 4, 0.5);
  nan.coeffRef(3, 3) = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(SparseCholesky(nan).ok());
  try {
    const Factorization f(nan, {}, {});
    FAIL() << "a matrix with an infinite entry was factorized";
  } catch (const FactorizationFailed& e) {
    EXPECT_NE(std::string(e.what()).find("NaN or infinite"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace softshell::engine::internal
