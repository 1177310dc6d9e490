#include "kkt_operator.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <map>

namespace softshell::engine::internal {

KktOperator::KktOperator(std::shared_ptr<const Factorization> factor,
                         std::shared_ptr<const Eigen::SparseMatrix<double>> matrix, const Problem& p,
                         bool zero_energy_pins)
    : factor_(std::move(factor)), matrix_(std::move(matrix)), rows_(p.rows), problem_rows_(p.rows.size()) {
  const Factorization& f = *factor_;
  const Eigen::SparseMatrix<double>& a = *matrix_;
  std::vector<int32_t> extra;
  std::set_difference(p.fixed.begin(), p.fixed.end(), f.fixed().begin(), f.fixed().end(), std::back_inserter(extra));
  for (int32_t dof : extra) {
    Row row;
    row.terms = {{dof, 1.0}};
    row.scale = 1.0;
    row.source = "vertex constraint on control point " + std::to_string(dof / 3);
    rows_.push_back(std::move(row));
  }
  const std::vector<int32_t>& pins = f.pinned();
  const auto na = static_cast<Eigen::Index>(f.factored().size());
  const auto nq = static_cast<Eigen::Index>(pins.size());
  const auto nr = static_cast<Eigen::Index>(rows_.size());
  pin_index_.assign(static_cast<size_t>(a.rows()), -1);
  for (size_t q = 0; q < pins.size(); ++q) pin_index_[static_cast<size_t>(pins[q])] = static_cast<int32_t>(q);

  // H = [A_aQ | C_a^T] and M = [[A_QQ, C_Q^T], [C_Q, 0]], as in the linear solver.
  Eigen::MatrixXd h = Eigen::MatrixXd::Zero(na, nq + nr);
  Eigen::MatrixXd m = Eigen::MatrixXd::Zero(nq + nr, nq + nr);
  for (Eigen::Index q = 0; q < nq; ++q) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(a, pins[static_cast<size_t>(q)]); it; ++it) {
      const auto row = static_cast<int32_t>(it.row());
      if (const int32_t i = f.position(row); i >= 0) {
        h(i, q) = it.value();
      } else if (const int32_t q2 = pin_index_[static_cast<size_t>(row)]; q2 >= 0) {
        m(q2, q) = it.value();
      }
    }
  }
  for (Eigen::Index r = 0; r < nr; ++r) {
    for (const auto& [dof, coef] : rows_[static_cast<size_t>(r)].terms) {
      if (const int32_t i = f.position(dof); i >= 0) {
        h(i, nq + r) += coef;
      } else if (const int32_t q = pin_index_[static_cast<size_t>(dof)]; q >= 0) {
        m(nq + r, q) += coef;
        m(q, nq + r) += coef;
      } else {
        fail(ErrorCode::kInternal, "constrained solve: a row refers to a DOF the factor eliminates");
      }
    }
  }
  forward_h_ = f.forward(h);
  Eigen::MatrixXd schur = m;
  schur.noalias() -= forward_h_.transpose() * forward_h_;
  if (zero_energy_pins) schur.topLeftCorner(nq, nq).setZero();
  small_ = SmallSystem(schur);
}

Eigen::VectorXd KktOperator::solve(const Eigen::VectorXd& r, const Eigen::VectorXd& g) const {
  const Factorization& f = *factor_;
  const std::vector<int32_t>& pins = f.pinned();
  const auto na = static_cast<Eigen::Index>(f.factored().size());
  const auto nq = static_cast<Eigen::Index>(pins.size());
  const auto nr = static_cast<Eigen::Index>(rows_.size());
  Eigen::VectorXd ra(na), small_rhs = Eigen::VectorXd::Zero(nq + nr);
  for (Eigen::Index i = 0; i < na; ++i) ra[i] = r[f.factored()[static_cast<size_t>(i)]];
  for (Eigen::Index q = 0; q < nq; ++q) small_rhs[q] = r[pins[static_cast<size_t>(q)]];
  for (size_t k = 0; k < problem_rows_; ++k) small_rhs[nq + static_cast<Eigen::Index>(k)] = g[static_cast<Eigen::Index>(k)];
  const Eigen::VectorXd y_r = f.forward(ra);
  Eigen::VectorXd y = small_.solve(small_rhs - forward_h_.transpose() * y_r);
  const Eigen::VectorXd z_a = f.backward(y_r - forward_h_ * y);
  Eigen::VectorXd z = Eigen::VectorXd::Zero(r.size());
  for (Eigen::Index i = 0; i < na; ++i) z[f.factored()[static_cast<size_t>(i)]] = z_a[i];
  for (Eigen::Index q = 0; q < nq; ++q) z[pins[static_cast<size_t>(q)]] = y[q];
  return z;
}

Reactions::Reactions(const Problem& p) : p_(p) {
  const auto nr = static_cast<Eigen::Index>(p.rows.size());
  if (nr == 0) return;
  // Gram matrix C C^T of the rows (their terms are on DOFs the problem does not prescribe).
  std::map<int32_t, std::vector<std::pair<Eigen::Index, double>>> by_dof;
  for (Eigen::Index r = 0; r < nr; ++r) {
    for (const auto& [dof, coef] : p.rows[static_cast<size_t>(r)].terms) by_dof[dof].push_back({r, coef});
  }
  Eigen::MatrixXd gram = Eigen::MatrixXd::Zero(nr, nr);
  for (const auto& [dof, entries] : by_dof) {
    for (const auto& [r1, c1] : entries) {
      for (const auto& [r2, c2] : entries) gram(r1, r2) += c1 * c2;
    }
  }
  gram_.setThreshold(1e-12);
  gram_.compute(gram);
}

Eigen::VectorXd Reactions::out_of_balance(const Eigen::VectorXd& r) const {
  Eigen::VectorXd out = r;
  for (int32_t dof : p_.fixed) out[dof] = 0.0;
  const auto nr = static_cast<Eigen::Index>(p_.rows.size());
  if (nr == 0) return out;
  Eigen::VectorXd cr(nr);
  for (Eigen::Index k = 0; k < nr; ++k) {
    double s = 0.0;
    for (const auto& [dof, coef] : p_.rows[static_cast<size_t>(k)].terms) s += coef * out[dof];
    cr[k] = s;
  }
  const Eigen::VectorXd mu = gram_.solve(cr);
  for (Eigen::Index k = 0; k < nr; ++k) {
    for (const auto& [dof, coef] : p_.rows[static_cast<size_t>(k)].terms) out[dof] -= coef * mu[k];
  }
  return out;
}

}  // namespace softshell::engine::internal
