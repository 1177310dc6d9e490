#include "factorization.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <string>

#include "cholesky_factor.h"
#include "hash_mix.h"

namespace softshell::engine::internal {
namespace {

std::atomic<uint64_t> g_next_factor_id{1};

// |K z|_i / (|K| |z|)_i up to which a pinned motion counts as zero-energy (round-off of a sum of
// a few hundred terms, with margin).
constexpr double kZeroEnergyResidual = 1e-11;

uint64_t pattern_hash(const Eigen::SparseMatrix<double>& a) {
  uint64_t h = hash_mix(0x243f6a8885a308d3ULL, static_cast<uint64_t>(a.cols()));
  for (Eigen::Index j = 0; j <= a.cols(); ++j) h = hash_mix(h, static_cast<uint64_t>(a.outerIndexPtr()[j]));
  for (Eigen::Index p = 0; p < a.nonZeros(); ++p) h = hash_mix(h, static_cast<uint64_t>(a.innerIndexPtr()[p]));
  return h;
}

// The upper triangle of `a` (symmetric, either triangle or both stored) in compressed CSC,
// restricted and renumbered by `position` (-1: left out) to `n` rows and columns.
Eigen::SparseMatrix<double> upper_part(const Eigen::SparseMatrix<double>& a, const std::vector<int32_t>& position,
                                       const std::vector<int32_t>& columns) {
  const auto n = static_cast<Eigen::Index>(columns.size());
  Eigen::SparseMatrix<double> out(n, n);
  Eigen::VectorXi count = Eigen::VectorXi::Zero(n);
  for (Eigen::Index j = 0; j < n; ++j) {
    const int32_t col = columns[static_cast<size_t>(j)];
    for (Eigen::SparseMatrix<double>::InnerIterator it(a, col); it; ++it) {
      if (it.row() <= col && position[static_cast<size_t>(it.row())] >= 0) ++count[j];
    }
  }
  out.reserve(count);
  for (Eigen::Index j = 0; j < n; ++j) {
    const int32_t col = columns[static_cast<size_t>(j)];
    for (Eigen::SparseMatrix<double>::InnerIterator it(a, col); it; ++it) {
      const int32_t row = position[static_cast<size_t>(it.row())];
      if (it.row() <= col && row >= 0) out.insert(row, j) = it.value();
    }
  }
  out.makeCompressed();
  return out;
}

}  // namespace

Factorization::Factorization(const ShellModel& model, std::vector<int32_t> fixed, std::vector<int32_t> pinned,
                             const Eigen::MatrixXd& motions)
    : id_(g_next_factor_id++), fixed_(std::move(fixed)), pinned_(std::move(pinned)),
      executor_(model.options().threads == 1 ? nullptr
                : model.options().executor ? model.options().executor
                                           : default_executor()) {
  const auto start = std::chrono::steady_clock::now();
  factorize(model.stiffness(), nullptr, SweepPrecision::kDouble);
  compute_pin_block(model.stiffness(), motions);
  factor_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

Factorization::Factorization(const Eigen::SparseMatrix<double>& k, std::vector<int32_t> fixed,
                             std::vector<int32_t> pinned, const Factorization* same_pattern,
                             const Eigen::MatrixXd& motions, std::shared_ptr<Executor> executor,
                             SweepPrecision precision)
    : id_(g_next_factor_id++), fixed_(std::move(fixed)), pinned_(std::move(pinned)), executor_(std::move(executor)) {
  const auto start = std::chrono::steady_clock::now();
  if (same_pattern && (same_pattern->fixed_ != fixed_ || same_pattern->pinned_ != pinned_ ||
                       same_pattern->position_.size() != static_cast<size_t>(k.rows()))) {
    same_pattern = nullptr;
  }
  factorize(k, same_pattern, precision);
  compute_pin_block(k, motions);
  factor_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

void Factorization::factorize(const Eigen::SparseMatrix<double>& k, const Factorization* same_pattern,
                              SweepPrecision precision) {
  if (k.rows() != k.cols()) fail(ErrorCode::kInternal, "Factorization: the matrix is not square");
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
  bytes_ = (2 * n + fixed_.size() + pinned_.size() + factored_.size()) * sizeof(int32_t);
  if (factored_.empty()) return;  // everything fixed (or pinned): nothing to factor

  const Eigen::SparseMatrix<double> a = upper_part(k, position_, factored_);
  pattern_hash_ = pattern_hash(a);
  const CholeskyFactor* reuse =
      same_pattern && same_pattern->factor_ && same_pattern->pattern_hash_ == pattern_hash_ ? same_pattern->factor_.get()
                                                                                          : nullptr;
  CholeskyFactor::Failure failure;
  factor_ = CholeskyFactor::factorize(a, reuse, failure, executor_.get(), precision);
  if (!factor_) {
    if (failure.out_of_memory) fail(ErrorCode::kResourceExhausted, "not enough memory to factorize K");
    const int32_t dof = failure.column >= 0 && static_cast<size_t>(failure.column) < factored_.size()
                            ? factored_[static_cast<size_t>(failure.column)]
                            : -1;
    if (failure.not_finite) {
      throw FactorizationFailed(ErrorCode::kUnprocessable,
          "the stiffness matrix holds NaN or infinite values" +
              (dof >= 0 ? " (reached at control point " + std::to_string(dof / 3) + ", axis " +
                              std::string(1, "xyz"[dof % 3]) + ")"
                        : std::string()) +
              ": check the mesh and the material for non-finite or degenerate values");
    }
    throw FactorizationFailed(ErrorCode::kUnprocessable,
         "the stiffness matrix with the prescribed DOFs removed is not positive definite" +
             (dof >= 0 ? " (first failing pivot: control point " + std::to_string(dof / 3) + ", axis " +
                             std::string(1, "xyz"[dof % 3]) + ")"
                       : std::string()) +
             ": part of the shell can move without strain; add constraints there");
  }
  reused_analysis_ = reuse != nullptr;
  bytes_ += factor_->bytes();
}

void Factorization::compute_pin_block(const Eigen::SparseMatrix<double>& k, const Eigen::MatrixXd& motions) {
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
  bytes_ += static_cast<size_t>(pin_columns_.size() + pin_block_.size()) * sizeof(double) +
            pin_position_.size() * sizeof(int32_t);
}

Factorization::~Factorization() = default;

Eigen::MatrixXd Factorization::forward(const Eigen::MatrixXd& rhs, double* fraction_read) const {
  if (fraction_read) *fraction_read = 1.0;
  if (!factor_ || rhs.cols() == 0) return Eigen::MatrixXd::Zero(rhs.rows(), rhs.cols());
  return factor_->forward(rhs, fraction_read, executor_.get());
}

Eigen::MatrixXd Factorization::backward(const Eigen::MatrixXd& y) const {
  if (!factor_ || y.cols() == 0) return Eigen::MatrixXd::Zero(y.rows(), y.cols());
  return factor_->backward(y, executor_.get());
}

bool Factorization::single_precision_sweeps() const { return factor_ && factor_->single_precision_sweeps(); }

bool Factorization::two_thread_sweeps() const {
  return factor_ && executor_ && executor_->concurrency() > 1 && factor_->two_thread_sweeps();
}

SparseCholesky::SparseCholesky(const Eigen::SparseMatrix<double>& a) {
  const auto n = static_cast<size_t>(a.rows());
  if (n == 0) return;
  std::vector<int32_t> position(n), columns(n);
  for (size_t i = 0; i < n; ++i) position[i] = columns[i] = static_cast<int32_t>(i);
  CholeskyFactor::Failure failure;
  factor_ = CholeskyFactor::factorize(upper_part(a, position, columns), nullptr, failure);
  if (!factor_) {
    if (failure.out_of_memory) fail(ErrorCode::kResourceExhausted, "not enough memory for the zero-mode analysis");
    return;
  }
  min_pivot_ = factor_->min_pivot();
}

SparseCholesky::~SparseCholesky() = default;

Eigen::MatrixXd SparseCholesky::solve(const Eigen::MatrixXd& rhs) const {
  if (!factor_) fail(ErrorCode::kInternal, "SparseCholesky::solve without a factor");
  if (rhs.cols() == 0) return rhs;
  return factor_->backward(factor_->forward(rhs));
}

}  // namespace softshell::engine::internal
