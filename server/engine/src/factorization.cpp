#include "factorization.h"

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <string>

#include <cholmod.h>
#include <dlfcn.h>

namespace softshell::engine::internal {
namespace {

// CHOLMOD keeps its workspace and settings in a cholmod_common; one per thread lets many solves
// run at once on a shared (read-only) factor.
struct ThreadCommon {
  cholmod_common common;
  ThreadCommon() {
    cholmod_start(&common);
    common.print = 0;        // errors are reported through our own messages
    common.error_handler = nullptr;
    common.supernodal = CHOLMOD_AUTO;
    common.final_ll = 1;     // keep L L^T: the solve is two triangular sweeps
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

std::atomic<uint64_t> g_next_factor_id{1};

// |K z|_i / (|K| |z|)_i up to which a pinned motion counts as zero-energy (round-off of a sum of
// a few hundred terms, with margin).
constexpr double kZeroEnergyResidual = 1e-11;

}  // namespace

Factorization::Factorization(const ShellModel& model, std::vector<int32_t> fixed, std::vector<int32_t> pinned,
                             const Eigen::MatrixXd& motions)
    : id_(g_next_factor_id++), fixed_(std::move(fixed)), pinned_(std::move(pinned)) {
  const auto start = std::chrono::steady_clock::now();
  const Eigen::SparseMatrix<double>& k = model.stiffness();
  const auto n = static_cast<size_t>(k.rows());
  position_.assign(n, -1);
  std::vector<char> excluded(n, 0);
  for (int32_t d : fixed_) excluded[static_cast<size_t>(d)] = 1;
  for (int32_t d : pinned_) excluded[static_cast<size_t>(d)] = 1;
  for (size_t d = 0; d < n; ++d) {
    if (!excluded[d]) {
      position_[d] = static_cast<int32_t>(factored_.size());
      factored_.push_back(static_cast<int32_t>(d));
    }
  }
  if (factored_.empty()) {  // everything fixed (or pinned): nothing to factor
    compute_pin_block(model, motions);
    return;
  }

  // Upper triangle of K_aa in CSC (CHOLMOD stype = 1).
  size_t nnz = 0;
  for (int32_t col : factored_) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(k, col); it; ++it) {
      if (it.row() <= col && position_[static_cast<size_t>(it.row())] >= 0) ++nnz;
    }
  }
  cholmod_common* c = thread_common();
  const size_t na = factored_.size();
  cholmod_sparse* a = cholmod_allocate_sparse(na, na, nnz, 1, 1, 1, CHOLMOD_REAL, c);
  if (!a) fail(ErrorCode::kResourceExhausted, "not enough memory for the stiffness matrix of this constraint set");
  auto* ap = static_cast<int*>(a->p);
  auto* ai = static_cast<int*>(a->i);
  auto* ax = static_cast<double*>(a->x);
  size_t pos = 0;
  for (size_t j = 0; j < na; ++j) {
    ap[j] = static_cast<int>(pos);
    const int32_t col = factored_[j];
    for (Eigen::SparseMatrix<double>::InnerIterator it(k, col); it; ++it) {
      const int32_t row = position_[static_cast<size_t>(it.row())];
      if (it.row() <= col && row >= 0) {
        ai[pos] = row;
        ax[pos] = it.value();
        ++pos;
      }
    }
  }
  ap[na] = static_cast<int>(pos);

  cholmod_factor* l = nullptr;
  bool ok = false;
  {
    const auto turn = blas_turn();
    l = cholmod_analyze(a, c);
    ok = l && cholmod_factorize(a, l, c) && c->status == CHOLMOD_OK && l->minor == l->n;
  }
  const size_t minor = l ? l->minor : 0;
  cholmod_free_sparse(&a, c);
  if (!ok) {
    if (l) cholmod_free_factor(&l, c);
    if (c->status == CHOLMOD_OUT_OF_MEMORY) fail(ErrorCode::kResourceExhausted, "not enough memory to factorize K");
    const int32_t dof = minor < na ? factored_[minor] : -1;
    throw FactorizationFailed(ErrorCode::kUnprocessable,
         "the stiffness matrix with the prescribed DOFs removed is not positive definite" +
             (dof >= 0 ? " (first failing pivot: control point " + std::to_string(dof / 3) + ", axis " +
                             std::string(1, "xyz"[dof % 3]) + ")"
                       : std::string()) +
             ": part of the shell can move without strain; add constraints there");
  }
  factor_ = reinterpret_cast<cholmod_factor_struct*>(l);
  if (l->is_super) {
    const auto* super = static_cast<const int*>(l->super);
    supernode_of_.resize(l->n);
    for (size_t s = 0; s < l->nsuper; ++s) {
      for (int col = super[s]; col < super[s + 1]; ++col) supernode_of_[static_cast<size_t>(col)] = static_cast<int32_t>(s);
    }
  }
  const size_t int_size = sizeof(int);
  bytes_ = l->is_super ? l->xsize * sizeof(double) + l->ssize * int_size + (3 * l->nsuper + 3) * int_size
                       : l->nzmax * (sizeof(double) + int_size);
  bytes_ += 4 * l->n * int_size + n * sizeof(int32_t) + factored_.size() * sizeof(int32_t) +
            supernode_of_.size() * sizeof(int32_t);
  compute_pin_block(model, motions);
  bytes_ += static_cast<size_t>(pin_columns_.size() + pin_block_.size()) * sizeof(double) +
            pin_position_.size() * sizeof(int32_t);
  factor_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

void Factorization::compute_pin_block(const ShellModel& model, const Eigen::MatrixXd& motions) {
  const Eigen::SparseMatrix<double>& k = model.stiffness();
  const auto na = static_cast<Eigen::Index>(factored_.size());
  const auto nq = static_cast<Eigen::Index>(pinned_.size());
  Eigen::MatrixXd kaq = Eigen::MatrixXd::Zero(na, nq);
  Eigen::MatrixXd kqq = Eigen::MatrixXd::Zero(nq, nq);
  pin_position_.assign(static_cast<size_t>(k.rows()), -1);
  for (size_t q = 0; q < pinned_.size(); ++q) pin_position_[static_cast<size_t>(pinned_[q])] = static_cast<int32_t>(q);
  for (Eigen::Index q = 0; q < nq; ++q) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(k, pinned_[static_cast<size_t>(q)]); it; ++it) {
      if (const int32_t a = position_[static_cast<size_t>(it.row())]; a >= 0) {
        kaq(a, q) = it.value();
      } else if (const int32_t q2 = pin_position_[static_cast<size_t>(it.row())]; q2 >= 0) {
        kqq(q2, q) = it.value();
      }
    }
  }
  pin_columns_ = nq ? forward(kaq) : Eigen::MatrixXd(na, 0);
  pin_block_ = kqq;
  pin_block_.noalias() -= pin_columns_.transpose() * pin_columns_;
  // Are the pinned motions zero-energy to round-off? |K z|_i against (|K| |z|)_i on every DOF
  // not fixed, for each motion (exact modes leave ~1e-16 .. 1e-14; a bending mode of a thin
  // shell mistaken for one would leave ~1e-4).
  pin_motion_residual_ = 0.0;
  if (nq > 0 && motions.cols() == nq && motions.rows() == k.rows()) {
    std::vector<char> fixed(static_cast<size_t>(k.rows()), 0);
    for (int32_t d : fixed_) fixed[static_cast<size_t>(d)] = 1;
    const Eigen::MatrixXd kz = k * motions;
    Eigen::MatrixXd size = Eigen::MatrixXd::Zero(k.rows(), nq);
    for (Eigen::Index j = 0; j < k.outerSize(); ++j) {
      const Eigen::RowVectorXd z = motions.row(j).cwiseAbs();
      if (z.isZero(0.0)) continue;
      for (Eigen::SparseMatrix<double>::InnerIterator it(k, j); it; ++it) size.row(it.row()) += std::abs(it.value()) * z;
    }
    for (Eigen::Index i = 0; i < k.rows(); ++i) {
      if (fixed[static_cast<size_t>(i)]) continue;
      for (Eigen::Index q = 0; q < nq; ++q) {
        const double r = std::abs(kz(i, q));
        if (r > 0.0) pin_motion_residual_ = std::max(pin_motion_residual_, size(i, q) > 0.0 ? r / size(i, q) : 1.0);
      }
    }
    pin_block_zeroed_ = pin_motion_residual_ <= kZeroEnergyResidual;
  } else {
    pin_block_zeroed_ = nq == 0;
  }
  if (pin_block_zeroed_) pin_block_.setZero();
}

Factorization::~Factorization() {
  if (factor_) {
    auto* l = reinterpret_cast<cholmod_factor*>(factor_);
    cholmod_free_factor(&l, thread_common());
  }
}

// Runs CHOLMOD's solve of `system` (CHOLMOD_L, _Lt, _P, _Pt) on a block of right-hand sides.
Eigen::MatrixXd Factorization::apply(int system, const Eigen::MatrixXd& rhs) const {
  if (!factor_ || rhs.cols() == 0) return Eigen::MatrixXd::Zero(rhs.rows(), rhs.cols());
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
    x = cholmod_solve(system, reinterpret_cast<cholmod_factor*>(factor_), &b, c);
  }
  if (!x) fail(ErrorCode::kResourceExhausted, "not enough memory for the triangular solves");
  Eigen::MatrixXd out = Eigen::Map<const Eigen::MatrixXd>(static_cast<const double*>(x->x), rhs.rows(), rhs.cols());
  cholmod_free_dense(&x, c);
  return out;
}

Eigen::MatrixXd Factorization::forward(const Eigen::MatrixXd& rhs, double* fraction_read) const {
  Eigen::MatrixXd x;
  double fraction = 1.0;
  if (!sparse_forward(rhs, x, fraction)) x = apply(CHOLMOD_L, apply(CHOLMOD_P, rhs));
  if (fraction_read) *fraction_read = fraction;
  return x;
}

bool Factorization::sparse_forward(const Eigen::MatrixXd& rhs, Eigen::MatrixXd& x, double& fraction_read) const {
  const auto* l = reinterpret_cast<const cholmod_factor*>(factor_);
  if (!l || !l->is_super || l->xtype != CHOLMOD_REAL || l->dtype != CHOLMOD_DOUBLE || rhs.cols() == 0) return false;
  const auto* super = static_cast<const int*>(l->super);
  const auto* pi = static_cast<const int*>(l->pi);
  const auto* px = static_cast<const int*>(l->px);
  const auto* rows = static_cast<const int*>(l->s);
  const auto* perm = static_cast<const int*>(l->Perm);
  const auto* values = static_cast<const double*>(l->x);
  const auto n = static_cast<Eigen::Index>(l->n);
  const size_t nsuper = l->nsuper;

  // Which supernodes the sweep reaches: those holding a nonzero row of P B, and every supernode
  // that one of them updates (its off-diagonal rows), in ascending order (parents come later).
  std::vector<char> reached(nsuper, 0);
  for (Eigen::Index k = 0; k < n; ++k) {
    if (!rhs.row(perm ? perm[k] : k).isZero(0.0)) reached[static_cast<size_t>(supernode_of_[static_cast<size_t>(k)])] = 1;
  }
  size_t work = 0;
  for (size_t s = 0; s < nsuper; ++s) {
    if (!reached[s]) continue;
    const int ncols = super[s + 1] - super[s];
    work += static_cast<size_t>(pi[s + 1] - pi[s]) * static_cast<size_t>(ncols);
    if (2 * work > l->xsize) return false;  // most of the factor: CHOLMOD's BLAS sweep is faster
    for (int p = pi[s] + ncols; p < pi[s + 1]; ++p) reached[static_cast<size_t>(supernode_of_[static_cast<size_t>(rows[p])])] = 1;
  }

  x.resize(n, rhs.cols());
  for (Eigen::Index k = 0; k < n; ++k) x.row(k) = rhs.row(perm ? perm[k] : k);
  Eigen::MatrixXd update;
  for (size_t s = 0; s < nsuper; ++s) {
    if (!reached[s]) continue;
    // Supernode s: columns k1..k1+ncols-1, a column-major nrows x ncols block whose top square is
    // the lower-triangular diagonal block and whose other rows are listed in `rows`.
    const int k1 = super[s], ncols = super[s + 1] - k1, nrows = pi[s + 1] - pi[s];
    const Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>> block(values + px[s], nrows, ncols,
                                                                            Eigen::OuterStride<>(nrows));
    auto xs = x.middleRows(k1, ncols);
    if (xs.size() == 0) continue;  // no right-hand sides (an empty triangular solve is UB in Eigen)
    block.topRows(ncols).triangularView<Eigen::Lower>().solveInPlace(xs);
    if (nrows == ncols) continue;
    update.noalias() = block.bottomRows(nrows - ncols) * xs;
    for (int i = 0; i < nrows - ncols; ++i) x.row(rows[pi[s] + ncols + i]) -= update.row(i);
  }
  fraction_read = static_cast<double>(work) / static_cast<double>(l->xsize);
  return true;
}

Eigen::MatrixXd Factorization::backward(const Eigen::MatrixXd& y) const {
  return apply(CHOLMOD_Pt, apply(CHOLMOD_Lt, y));
}

SparseCholesky::SparseCholesky(const Eigen::SparseMatrix<double>& a) {
  const auto n = static_cast<size_t>(a.rows());
  if (n == 0) return;
  size_t nnz = 0;
  for (Eigen::Index j = 0; j < a.outerSize(); ++j) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(a, j); it; ++it) nnz += it.row() <= j;
  }
  cholmod_common* c = thread_common();
  cholmod_sparse* m = cholmod_allocate_sparse(n, n, nnz, 1, 1, 1, CHOLMOD_REAL, c);
  if (!m) fail(ErrorCode::kResourceExhausted, "not enough memory for the zero-mode analysis");
  auto* mp = static_cast<int*>(m->p);
  auto* mi = static_cast<int*>(m->i);
  auto* mx = static_cast<double*>(m->x);
  size_t pos = 0;
  for (Eigen::Index j = 0; j < a.outerSize(); ++j) {
    mp[j] = static_cast<int>(pos);
    for (Eigen::SparseMatrix<double>::InnerIterator it(a, j); it; ++it) {
      if (it.row() > j) continue;
      mi[pos] = static_cast<int>(it.row());
      mx[pos] = it.value();
      ++pos;
    }
  }
  mp[n] = static_cast<int>(pos);
  cholmod_factor* l = nullptr;
  bool ok = false;
  {
    const auto turn = blas_turn();
    l = cholmod_analyze(m, c);
    ok = l && cholmod_factorize(m, l, c) && c->status == CHOLMOD_OK && l->minor == l->n;
  }
  cholmod_free_sparse(&m, c);
  const bool out_of_memory = c->status == CHOLMOD_OUT_OF_MEMORY;
  if (!ok) {
    if (l) cholmod_free_factor(&l, c);
    if (out_of_memory) fail(ErrorCode::kResourceExhausted, "not enough memory for the zero-mode analysis");
    return;
  }
  // The pivots: the squared diagonal of L (supernodal: the diagonal of each supernode's block).
  double low = std::numeric_limits<double>::infinity();
  const auto* x = static_cast<const double*>(l->x);
  if (l->is_super) {
    const auto* super = static_cast<const int*>(l->super);
    const auto* pi = static_cast<const int*>(l->pi);
    const auto* px = static_cast<const int*>(l->px);
    for (size_t s = 0; s < l->nsuper; ++s) {
      const int ncols = super[s + 1] - super[s], nrows = pi[s + 1] - pi[s];
      for (int j = 0; j < ncols; ++j) low = std::min(low, x[px[s] + static_cast<ptrdiff_t>(j) * (nrows + 1)]);
    }
    low *= low;
  } else {
    const auto* p = static_cast<const int*>(l->p);
    for (size_t j = 0; j < l->n; ++j) low = std::min(low, x[p[j]]);
    if (l->is_ll) low *= low;  // LDL^T keeps D on the diagonal
  }
  factor_ = reinterpret_cast<cholmod_factor_struct*>(l);
  min_pivot_ = low;
}

SparseCholesky::~SparseCholesky() {
  if (factor_) {
    auto* l = reinterpret_cast<cholmod_factor*>(factor_);
    cholmod_free_factor(&l, thread_common());
  }
}

Eigen::MatrixXd SparseCholesky::solve(const Eigen::MatrixXd& rhs) const {
  if (!factor_) fail(ErrorCode::kInternal, "SparseCholesky::solve without a factor");
  if (rhs.cols() == 0) return rhs;
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
    x = cholmod_solve(CHOLMOD_A, reinterpret_cast<cholmod_factor*>(factor_), &b, c);
  }
  if (!x) fail(ErrorCode::kResourceExhausted, "not enough memory for the zero-mode analysis");
  Eigen::MatrixXd out = Eigen::Map<const Eigen::MatrixXd>(static_cast<const double*>(x->x), rhs.rows(), rhs.cols());
  cholmod_free_dense(&x, c);
  return out;
}

}  // namespace softshell::engine::internal
