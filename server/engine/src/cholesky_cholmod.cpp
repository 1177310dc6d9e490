// The CHOLMOD implementation of CholeskyFactor (SOFTSHELL_SPARSE_CHOLESKY=cholmod): CHOLMOD's
// analysis (ordering, supernodes) and supernodal factor (simplicial when CHOLMOD finds that
// faster), filled by our numeric factorization (supernodal_numeric.h; CHOLMOD's own for a
// simplicial factor), its BLAS-based solves, and sweeps of our own (supernodal_sweeps.h): forward
// over the supernodes local right-hand sides reach, and whole sweeps on two threads over a large
// factor.
#include "cholesky_factor.h"

#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <iterator>
#include <limits>
#include <mutex>
#include <vector>

#include <cholmod.h>
#include <dlfcn.h>

#include "softshell/result.h"
#include "supernodal_numeric.h"
#include "supernodal_sweeps.h"

namespace softshell::engine::internal {

std::atomic<size_t> g_spare_factor_bytes{8u << 20};

namespace {

// CHOLMOD's settings for a factorization of `rows` rows (all of them: a thread's common keeps
// what the last call set). The fill-reducing ordering is CHOLMOD's default (AMD, and METIS too
// when AMD's factor comes out dense) unless the matrix is large: there CHOLMOD's nested
// dissection (METIS on the separators, CAMD on the parts) factors fastest and pays for its
// slower analysis at once. Measured (docs/benchmarks.md, "The ordering"): spot_quadrangulated's K
// 127 ms a factorization against the default's 258 ms (METIS), roof 181x181 3.8 s against 4.6 s.
// Below a few thousand DOFs the orderings factor alike and AMD's analysis is the cheapest.
void configure(cholmod_common* c, size_t rows) {
  cholmod_defaults(c);
  c->print = 0;  // errors are reported through our own messages
  c->error_handler = nullptr;
  c->supernodal = CHOLMOD_AUTO;
  c->final_ll = 1;  // keep L L^T: the solve is two triangular sweeps
  // (Supernodal factors are filled by supernodal_numeric.h, which stops at the first failing
  // supernode. Should CHOLMOD's own numeric factorization run one, it stops there too, instead of
  // factoring that supernode again up to the failed column for a partial factor nobody reads.)
  c->quick_return_if_not_posdef = 1;
  // Supernodes amalgamated twice as far as CHOLMOD's defaults (4/16/48 columns, 80/10/5% zeros):
  // a shell's matrix has 3 x 3 blocks and small separators, and on fewer, larger supernodes the
  // dense kernels pay off. Measured on 2 cores with CHOLMOD's numeric factorization:
  // catmark_righthanded's factor 12.3-12.9 -> 6.9-8.2 ms, spot_quadrangulated's 71-122 -> 63-91
  // ms, blub's unchanged; 10-18% more stored entries, solves as fast (four times as far: spot
  // 169-197 ms). With ours (supernodal_numeric.h), four times as far was slower on
  // catmark_righthanded's tangent too (9.1-9.4 against 6.9-7.9 ms; docs/benchmarks.md).
  c->nrelax[0] = 8;
  c->nrelax[1] = 32;
  c->nrelax[2] = 96;
  c->zrelax[0] = 0.8;
  c->zrelax[1] = 0.2;
  c->zrelax[2] = 0.1;
  constexpr size_t kNestedDissectionFrom = 6000;
  if (rows >= kNestedDissectionFrom) {
    c->nmethods = 2;  // CHOLMOD tries both and keeps the better
    c->method[0].ordering = CHOLMOD_AMD;
    c->method[1].ordering = CHOLMOD_NESDIS;
  }
}

// CHOLMOD keeps its workspace and settings in a cholmod_common; one per thread lets many solves
// run at once on a shared (read-only) factor.
struct ThreadCommon {
  cholmod_common common;
  ThreadCommon() {
    cholmod_start(&common);
    configure(&common, 0);
  }
  ~ThreadCommon() { cholmod_finish(&common); }
  ThreadCommon(const ThreadCommon&) = delete;
  ThreadCommon& operator=(const ThreadCommon&) = delete;
};

cholmod_common* thread_common() {
  thread_local ThreadCommon common;
  return &common.common;
}

// CHOLMOD's supernodal factorization and solves call BLAS. OpenBLAS built without threading
// (Debian's libopenblas0-serial) keeps global buffers and is not safe to call from several
// threads at once: concurrent solves then return wrong numbers. Whatever BLAS the system loaded,
// ask it; if it is such an OpenBLAS, the engine's BLAS-using calls take turns. Reference BLAS and
// threaded OpenBLAS (libopenblas0-pthread, what build.sh installs) run concurrently.
//
// A threaded OpenBLAS is also told to use one thread per call (unless OPENBLAS_NUM_THREADS says
// otherwise): the service already runs solves in parallel, one per core, and BLAS threads on top
// would only oversubscribe the cores (measured: 2 concurrent clients got less throughput than 1).
//
// The probe runs once, when the engine library is loaded (BLAS is loaded before it, as CHOLMOD's
// dependency), so no kernel ever calls dlsym or changes BLAS settings.
struct BlasPolicy {
  bool thread_unsafe = false;  // calls must take turns
};

BlasPolicy probe_blas() {
  using Query = int (*)();
  auto query = reinterpret_cast<Query>(dlsym(RTLD_DEFAULT, "openblas_get_parallel"));
  if (query != nullptr && query() != 0 && std::getenv("OPENBLAS_NUM_THREADS") == nullptr) {
    using SetThreads = void (*)(int);
    if (auto set = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"))) set(1);
  }
  return BlasPolicy{query != nullptr && query() == 0};  // 0 = sequential build
}

const BlasPolicy g_blas = probe_blas();
std::mutex g_blas_mutex;

std::unique_lock<std::mutex> blas_turn() {
  return g_blas.thread_unsafe ? std::unique_lock<std::mutex>(g_blas_mutex) : std::unique_lock<std::mutex>();
}

// Large factors let go of are kept for the next factorization of the same analysis: CHOLMOD
// refactors a factor in place (cholmod_factorize on a numeric L), where a new factor is a copy in
// memory the allocator takes fresh from the system at this size, and on a VM a fresh page costs
// about 12 us. Measured on the 2-core EPYC VM: a refactorization of spot_quadrangulated's tangent
// (a 35 MB factor) faulted in 9,100 pages and took 200-215 ms; refactored in place, 102-138 ms.
// Smaller factors are left to the allocator, which reuses their memory (catmark_righthanded's
// 3.3 MB factor: kept, its refactorizations alternated between 9 and 14-16 ms, as CHOLMOD's
// temporaries then came from fresh pages every other time). At most two are kept, whatever
// their pattern (memory a host's budget does not see, so it stays small); a factor that a
// failed factorization left (columns from the failure on are zero) is as good as any.
class SpareFactors {
 public:
  SpareFactors() { cholmod_start(&common_); }
  ~SpareFactors() {
    const std::lock_guard<std::mutex> lock(mutex_);
    for (auto& [analysis, l] : spare_) cholmod_free_factor(&l, &common_);
    spare_.clear();
    alive_ = false;
    cholmod_finish(&common_);
  }
  SpareFactors(const SpareFactors&) = delete;
  SpareFactors& operator=(const SpareFactors&) = delete;

  // A kept factor of `analysis`, or null.
  cholmod_factor* take(uint64_t analysis) {
    const std::lock_guard<std::mutex> lock(mutex_);
    for (auto it = spare_.rbegin(); it != spare_.rend(); ++it) {
      if (it->first != analysis) continue;
      cholmod_factor* l = it->second;
      spare_.erase(std::next(it).base());
      return l;
    }
    return nullptr;
  }
  // Keeps l (supernodal, of `analysis`, at least g_spare_factor_bytes) for a later take,
  // dropping the oldest beyond two; frees anything else.
  void keep(uint64_t analysis, cholmod_factor* l) {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (!alive_ || !l->is_super || l->xsize * sizeof(double) < g_spare_factor_bytes.load()) {
      cholmod_free_factor(&l, &common_);
      return;
    }
    spare_.emplace_back(analysis, l);
    while (spare_.size() > kMaxSpare) {
      cholmod_free_factor(&spare_.front().second, &common_);
      spare_.erase(spare_.begin());
    }
  }

 private:
  static constexpr size_t kMaxSpare = 2;
  std::mutex mutex_;
  cholmod_common common_;  // for freeing (it only counts memory)
  std::vector<std::pair<uint64_t, cholmod_factor*>> spare_;  // oldest first
  bool alive_ = true;
};

// Built when the library loads, before any factor exists, so it outlives them all.
SpareFactors g_spare_factors;
// Each analysis (ordering and supernodes) gets an id; factors made from a copy of it share it.
std::atomic<uint64_t> g_next_analysis{1};

// Calls visit(column, diagonal entry of L) for every column until it returns true; the column
// where it did, or -1. (Supernodal: the diagonal of each supernode's dense block.)
template <class Visit>
Eigen::Index find_on_diagonal(const cholmod_factor* l, Visit&& visit) {
  const auto* x = static_cast<const double*>(l->x);
  if (l->is_super) {
    const auto* super = static_cast<const int*>(l->super);
    const auto* pi = static_cast<const int*>(l->pi);
    const auto* px = static_cast<const int*>(l->px);
    for (size_t s = 0; s < l->nsuper; ++s) {
      const int ncols = super[s + 1] - super[s], nrows = pi[s + 1] - pi[s];
      for (int j = 0; j < ncols; ++j) {
        if (visit(super[s] + j, x[px[s] + static_cast<ptrdiff_t>(j) * (nrows + 1)])) return super[s] + j;
      }
    }
    return -1;
  }
  const auto* p = static_cast<const int*>(l->p);
  for (size_t j = 0; j < l->n; ++j) {
    if (visit(static_cast<Eigen::Index>(j), x[p[j]])) return static_cast<Eigen::Index>(j);
  }
  return -1;
}

// The first column of L whose diagonal entry is NaN or infinite, or -1.
Eigen::Index first_nonfinite_pivot(const cholmod_factor* l) {
  return find_on_diagonal(l, [](Eigen::Index, double d) { return !std::isfinite(d); });
}

// What a supernodal analysis gives every factor made from it: the layout's offsets (CHOLMOD's
// ints widened), the ordering, and the plan for sweeps on two threads.
struct SupernodalPlan {
  std::vector<int32_t> supernode_of;  // per factor column
  std::vector<int64_t> row_start, value_start;
  std::vector<int32_t> position;  // position[i]: where row i of A is in the factor
  std::unique_ptr<const TwoThreadSweeps> sweeps;

  explicit SupernodalPlan(const cholmod_factor* l) {
    const auto* super = static_cast<const int*>(l->super);
    supernode_of.resize(l->n);
    for (size_t s = 0; s < l->nsuper; ++s) {
      for (int col = super[s]; col < super[s + 1]; ++col) supernode_of[static_cast<size_t>(col)] = static_cast<int32_t>(s);
    }
    row_start.assign(static_cast<const int*>(l->pi), static_cast<const int*>(l->pi) + l->nsuper + 1);
    value_start.assign(static_cast<const int*>(l->px), static_cast<const int*>(l->px) + l->nsuper + 1);
    position.resize(l->n);
    const auto* perm = static_cast<const int*>(l->Perm);
    for (size_t k = 0; k < l->n; ++k) position[static_cast<size_t>(perm ? perm[k] : static_cast<int>(k))] = static_cast<int32_t>(k);
    sweeps = TwoThreadSweeps::plan(layout(l));
  }
  // The layout of l, a factor of this analysis.
  SupernodalLayout layout(const cholmod_factor* l) const {
    SupernodalLayout out;
    out.supernodes = static_cast<int64_t>(l->nsuper);
    out.first = static_cast<const int*>(l->super);
    out.row_start = row_start.data();
    out.value_start = value_start.data();
    out.rows = static_cast<const int*>(l->s);
    out.supernode_of = supernode_of.data();
    out.values = static_cast<const double*>(l->x);
    return out;
  }
  size_t bytes() const {
    return (supernode_of.size() + position.size()) * sizeof(int32_t) +
           (row_start.size() + value_start.size()) * sizeof(int64_t) + (sweeps ? sweeps->bytes() : 0);
  }
};

}  // namespace

struct CholeskyFactor::State {
  cholmod_factor* l = nullptr;
  uint64_t analysis = 0;  // which analysis l is of (SpareFactors)
  std::shared_ptr<const SupernodalPlan> plan;  // a supernodal factor's, shared by its analysis' factors
  SupernodalLayout layout;
  std::unique_ptr<float[]> single;  // L rounded to single precision (SweepPrecision::kSingle)
  const TwoThreadSweeps* sweeps() const { return plan ? plan->sweeps.get() : nullptr; }
  ~State() {
    if (l) g_spare_factors.keep(analysis, l);
  }

  // Runs CHOLMOD's solve of `system` (CHOLMOD_L, _Lt, _P, _Pt, _A) on a block of right-hand sides.
  Eigen::MatrixXd apply(int system, const Eigen::MatrixXd& rhs) const;
  // The forward sweep over the supernodes reachable from the nonzero rows of P B (plan_forward),
  // unless that is most of the factor and one thread sweeps it: false (and `x` untouched), for
  // CHOLMOD's sweep is faster on one. (Not for a single-precision factor: CHOLMOD reads L itself.)
  bool own_forward(const Eigen::MatrixXd& rhs, Eigen::MatrixXd& x, double& fraction_read, Executor* executor) const;
};

CholeskyFactor::CholeskyFactor(std::unique_ptr<State> state) : state_(std::move(state)) {}
CholeskyFactor::~CholeskyFactor() = default;

const char* CholeskyFactor::backend() { return "CHOLMOD supernodal"; }

std::unique_ptr<CholeskyFactor> CholeskyFactor::factorize(const Eigen::SparseMatrix<double>& upper,
                                                          const CholeskyFactor* same_pattern, Failure& failure,
                                                          Executor* executor, SweepPrecision precision) {
  failure = Failure{};
  // A view of `upper` as a cholmod_sparse (stype 1: the upper triangle is read); CHOLMOD does not
  // write to its input.
  cholmod_sparse a;
  std::memset(&a, 0, sizeof a);
  a.nrow = a.ncol = static_cast<size_t>(upper.rows());
  a.nzmax = static_cast<size_t>(upper.nonZeros());
  a.p = const_cast<int*>(upper.outerIndexPtr());
  a.i = const_cast<int*>(upper.innerIndexPtr());
  a.x = const_cast<double*>(upper.valuePtr());
  a.stype = 1;
  a.itype = CHOLMOD_INT;
  a.xtype = CHOLMOD_REAL;
  a.dtype = CHOLMOD_DOUBLE;
  a.sorted = 1;
  a.packed = 1;

  cholmod_common* c = thread_common();
  const uint64_t analysis = same_pattern ? same_pattern->state_->analysis : g_next_analysis++;
  // A factor of the same analysis carries its ordering and supernodes: factorizing into it skips
  // the analysis. A kept one (SpareFactors) is refactored in place, else a copy is made.
  cholmod_factor* l = same_pattern ? g_spare_factors.take(analysis) : nullptr;
  {
    const auto turn = blas_turn();
    configure(c, a.nrow);
    if (!l) l = same_pattern ? cholmod_copy_factor(same_pattern->state_->l, c) : cholmod_analyze(&a, c);
  }
  if (!l) {
    failure.out_of_memory = c->status == CHOLMOD_OUT_OF_MEMORY;
    return nullptr;
  }
  auto state = std::make_unique<State>();
  state->analysis = analysis;
  bool ok = false;
  double min_diagonal = 0.0;  // min L_kk of a supernodal factor
  if (l->is_super) {
    // Ours (supernodal_numeric.h): into CHOLMOD's layout, given its values (a symbolic factor
    // fresh from the analysis has none yet).
    try {
      state->plan = same_pattern && same_pattern->state_->plan ? same_pattern->state_->plan
                                                               : std::make_shared<const SupernodalPlan>(l);
      ok = l->xtype == CHOLMOD_REAL || cholmod_change_factor(CHOLMOD_REAL, 1, 1, 1, 1, l, c);
      if (ok) {
        const SupernodalOutcome outcome =
            factor_supernodes(state->plan->layout(l), factor_order_entries(upper, state->plan->position),
                              upper.valuePtr(), static_cast<double*>(l->x), state->plan->sweeps.get(), executor);
        l->is_ll = 1;
        l->minor = outcome.failed_column >= 0 ? static_cast<size_t>(outcome.failed_column) : l->n;
        ok = outcome.failed_column < 0;
        min_diagonal = outcome.min_diagonal;
        failure.not_finite = outcome.not_finite;
      } else {
        failure.out_of_memory = c->status == CHOLMOD_OUT_OF_MEMORY;
      }
    } catch (const std::bad_alloc&) {
      failure.out_of_memory = true;
    }
  } else {
    const auto turn = blas_turn();
    ok = cholmod_factorize(&a, l, c) && c->status == CHOLMOD_OK && l->minor == l->n;
    failure.out_of_memory = c->status == CHOLMOD_OUT_OF_MEMORY;
  }
  // A pivot that is not positive stops either factorization, but NaN can pass CHOLMOD's
  // (simplicial: NaN <= 0 is false); a non-finite value anywhere in L reaches a later pivot
  // (L_kk^2 = A_kk - sum of squares of row k), so the pivots tell.
  if (ok) {
    const Eigen::Index bad = first_nonfinite_pivot(l);
    if (bad >= 0) {
      failure.not_finite = true;
      const auto* perm = static_cast<const int*>(l->Perm);
      failure.column = perm ? perm[bad] : bad;
      g_spare_factors.keep(analysis, l);
      return nullptr;
    }
  }
  if (!ok) {
    if (l->minor < l->n) {
      const auto* perm = static_cast<const int*>(l->Perm);
      failure.column = perm ? perm[l->minor] : static_cast<Eigen::Index>(l->minor);
    }
    if (failure.out_of_memory) {
      cholmod_free_factor(&l, c);
    } else {
      g_spare_factors.keep(analysis, l);
    }
    return nullptr;
  }
  state->l = l;
  if (state->plan) {
    state->layout = state->plan->layout(l);
    if (precision == SweepPrecision::kSingle) {
      state->single = single_copy(state->layout, upper, min_diagonal, executor);
      state->layout.single = state->single.get();
    }
  }
  return std::unique_ptr<CholeskyFactor>(new CholeskyFactor(std::move(state)));
}

Eigen::Index CholeskyFactor::size() const { return static_cast<Eigen::Index>(state_->l->n); }

size_t CholeskyFactor::bytes() const {
  const cholmod_factor* l = state_->l;
  const size_t int_size = sizeof(int);
  size_t bytes = l->is_super ? l->xsize * sizeof(double) + l->ssize * int_size + (3 * l->nsuper + 3) * int_size
                             : l->nzmax * (sizeof(double) + int_size);
  if (state_->plan) bytes += state_->plan->bytes();  // shared by its analysis' factors; counted with each
  if (state_->single) bytes += static_cast<size_t>(state_->layout.entries()) * sizeof(float);
  return bytes + 4 * l->n * int_size;
}

double CholeskyFactor::min_pivot() const {
  // The pivots: the squared diagonal of L (LDL^T keeps D itself on the diagonal).
  const cholmod_factor* l = state_->l;
  double low = std::numeric_limits<double>::infinity();
  find_on_diagonal(l, [&](Eigen::Index, double d) {
    low = std::min(low, d);
    return false;
  });
  return (l->is_super || l->is_ll) ? low * low : low;
}

Eigen::MatrixXd CholeskyFactor::State::apply(int system, const Eigen::MatrixXd& rhs) const {
  if (rhs.cols() == 0) return Eigen::MatrixXd::Zero(rhs.rows(), rhs.cols());
  cholmod_common* c = thread_common();
  cholmod_dense b;
  std::memset(&b, 0, sizeof b);
  b.nrow = static_cast<size_t>(rhs.rows());
  b.ncol = static_cast<size_t>(rhs.cols());
  b.nzmax = b.nrow * b.ncol;
  b.d = b.nrow;
  b.x = const_cast<double*>(rhs.data());  // read only
  b.xtype = CHOLMOD_REAL;
  b.dtype = CHOLMOD_DOUBLE;
  cholmod_dense* x = nullptr;
  {
    const auto turn = blas_turn();
    x = cholmod_solve(system, l, &b, c);
  }
  if (!x) fail(ErrorCode::kResourceExhausted, "not enough memory for the triangular solves");
  Eigen::MatrixXd out = Eigen::Map<const Eigen::MatrixXd>(static_cast<const double*>(x->x), rhs.rows(), rhs.cols());
  cholmod_free_dense(&x, c);
  return out;
}

namespace {

// Runs sweep(x), with one right-hand side as a vector (Eigen's vector kernels).
template <class Sweep>
void by_columns(Eigen::MatrixXd& x, Sweep&& sweep) {
  if (x.cols() != 1) {
    sweep(x);
    return;
  }
  Eigen::VectorXd v = x.col(0);
  sweep(v);
  x.col(0) = v;
}

}  // namespace

bool CholeskyFactor::State::own_forward(const Eigen::MatrixXd& rhs, Eigen::MatrixXd& x, double& fraction_read,
                                       Executor* executor) const {
  if (layout.supernodes == 0 || rhs.cols() == 0) return false;
  const auto* perm = static_cast<const int*>(l->Perm);
  const auto n = static_cast<Eigen::Index>(l->n);
  // Which supernodes the sweep reaches: those holding a nonzero row of P B, and every supernode
  // that one of them updates.
  std::vector<char> reached(static_cast<size_t>(layout.supernodes), 0);
  for (Eigen::Index k = 0; k < n; ++k) {
    if (!rhs.row(perm ? perm[k] : k).isZero(0.0)) reached[static_cast<size_t>(layout.supernode_of[k])] = 1;
  }
  const ForwardSweep route = plan_forward(layout, sweeps(), executor, reached);
  if (route.whole && !route.two_threads && !layout.single) return false;
  x.resize(n, rhs.cols());
  for (Eigen::Index k = 0; k < n; ++k) x.row(k) = rhs.row(perm ? perm[k] : k);
  if (route.two_threads) {
    const std::vector<char>* only = route.whole ? nullptr : &reached;
    by_columns(x, [&](auto& xs) { sweeps()->forward(layout, xs, *executor, only); });
    fraction_read = route.whole ? 1.0 : static_cast<double>(route.work) / static_cast<double>(layout.entries());
    return true;
  }
  by_columns(x, [&](auto& xs) { forward_sweep(layout, xs, reached); });
  fraction_read = static_cast<double>(route.work) / static_cast<double>(layout.entries());
  return true;
}

Eigen::MatrixXd CholeskyFactor::forward(const Eigen::MatrixXd& rhs, double* fraction_read, Executor* executor) const {
  Eigen::MatrixXd x;
  double fraction = 1.0;
  if (!state_->own_forward(rhs, x, fraction, executor)) x = state_->apply(CHOLMOD_L, state_->apply(CHOLMOD_P, rhs));
  if (fraction_read) *fraction_read = fraction;
  return x;
}

Eigen::MatrixXd CholeskyFactor::backward(const Eigen::MatrixXd& y, Executor* executor) const {
  const bool two_threads = on_two_threads(state_->sweeps(), executor);
  if ((!two_threads && !state_->single) || y.cols() == 0) {
    return state_->apply(CHOLMOD_Pt, state_->apply(CHOLMOD_Lt, y));
  }
  Eigen::MatrixXd x = y;
  by_columns(x, [&](auto& xs) {
    if (two_threads) {
      state_->sweeps()->backward(state_->layout, xs, *executor);
    } else {
      backward_sweep(state_->layout, xs);
    }
  });
  const auto* perm = static_cast<const int*>(state_->l->Perm);
  if (!perm) return x;
  Eigen::MatrixXd out(x.rows(), x.cols());
  for (Eigen::Index k = 0; k < x.rows(); ++k) out.row(perm[k]) = x.row(k);
  return out;
}

bool CholeskyFactor::two_thread_sweeps() const { return state_->sweeps() != nullptr; }

bool CholeskyFactor::single_precision_sweeps() const { return state_->single != nullptr; }

}  // namespace softshell::engine::internal
