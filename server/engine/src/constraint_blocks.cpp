#include "constraint_blocks.h"

#include <cmath>
#include <cstring>

#include <Eigen/Dense>

#include "softshell/result.h"

namespace softshell::engine::internal {
namespace {

// A kept row's pivot N_rr - |l|^2 must be at least this share of N_rr; below it the row is
// (nearly) a combination of earlier ones and is left to the small system's decomposition, which
// handles redundancy. 1e-8 keeps cond(N) <= 1e8 on the kept rows.
constexpr double kDeferPivot = 1e-8;

// b <- L^-1 b. Eigen's triangular solve takes the address of the first coefficient, which an
// empty matrix does not have (UBSan: reference binding to null), so empty systems return here.
template <typename Lower, typename Rhs>
void solve_lower_in_place(const Lower& l, Rhs&& b) {
  if (l.rows() == 0 || b.size() == 0) return;
  l.template triangularView<Eigen::Lower>().solveInPlace(b);
}

uint64_t mix(uint64_t h, uint64_t x) { return hash_mix(h, x); }

// The columns C^T of rows on the factored DOFs (dense: factor rows x rows; skipped if null) and
// their coefficients on the pins (pins x rows).
void row_columns(const Factorization& factor, const std::vector<Terms>& rows, Eigen::MatrixXd* on_factored,
                 Eigen::MatrixXd& on_pins) {
  const auto na = static_cast<Eigen::Index>(factor.factored().size());
  const auto nq = static_cast<Eigen::Index>(factor.pinned().size());
  if (on_factored) on_factored->setZero(na, static_cast<Eigen::Index>(rows.size()));
  on_pins.setZero(nq, static_cast<Eigen::Index>(rows.size()));
  for (size_t r = 0; r < rows.size(); ++r) {
    for (const auto& [dof, coef] : rows[r]) {
      if (const int32_t a = factor.position(dof); a >= 0) {
        if (on_factored) (*on_factored)(a, static_cast<Eigen::Index>(r)) += coef;
      } else if (const int32_t q = factor.pin_position(dof); q >= 0) {
        on_pins(q, static_cast<Eigen::Index>(r)) += coef;
      } else {
        fail(ErrorCode::kInternal, "solver: a constraint row refers to a DOF the factor eliminates");
      }
    }
  }
}

}  // namespace


uint64_t hash_terms(const Terms& terms) {
  uint64_t h = 0x243f6a8885a308d3ULL ^ terms.size();
  for (const auto& [dof, coef] : terms) {
    uint64_t bits = 0;
    std::memcpy(&bits, &coef, sizeof bits);
    h = mix(mix(h, static_cast<uint64_t>(dof)), bits);
  }
  return h;
}

SweptColumns SweptColumns::compress(const Eigen::MatrixXd& y) {
  SweptColumns out;
  for (Eigen::Index i = 0; i < y.rows(); ++i) {
    if (!y.row(i).isZero(0.0)) out.rows.push_back(static_cast<int32_t>(i));
  }
  out.values.resize(static_cast<Eigen::Index>(out.rows.size()), y.cols());
  for (size_t k = 0; k < out.rows.size(); ++k) out.values.row(static_cast<Eigen::Index>(k)) = y.row(out.rows[k]);
  return out;
}

Eigen::MatrixXd SweptColumns::transpose_times(const Eigen::MatrixXd& x, const std::vector<char>* nonzero) const {
  if (!nonzero) {
    Eigen::MatrixXd gathered(static_cast<Eigen::Index>(rows.size()), x.cols());
    for (size_t k = 0; k < rows.size(); ++k) gathered.row(static_cast<Eigen::Index>(k)) = x.row(rows[k]);
    return values.transpose() * gathered;
  }
  std::vector<Eigen::Index> local;
  for (size_t k = 0; k < rows.size(); ++k) {
    if ((*nonzero)[static_cast<size_t>(rows[k])]) local.push_back(static_cast<Eigen::Index>(k));
  }
  const auto m = static_cast<Eigen::Index>(local.size());
  Values v(m, values.cols());
  Eigen::MatrixXd gathered(m, x.cols());
  for (Eigen::Index i = 0; i < m; ++i) {
    v.row(i) = values.row(local[static_cast<size_t>(i)]);
    gathered.row(i) = x.row(rows[static_cast<size_t>(local[static_cast<size_t>(i)])]);
  }
  return v.transpose() * gathered;
}

void SweptColumns::add_times(const Eigen::Ref<const Eigen::VectorXd>& c, Eigen::VectorXd& out) const {
  const Eigen::VectorXd product = values * c;
  for (size_t k = 0; k < rows.size(); ++k) out[rows[k]] += product[static_cast<Eigen::Index>(k)];
}

size_t SweptColumns::bytes() const {
  return sizeof(SweptColumns) + rows.size() * sizeof(int32_t) + static_cast<size_t>(values.size()) * sizeof(double);
}

Eigen::MatrixXd ConstraintBlock::transpose_times(const Eigen::MatrixXd& x, const std::vector<char>* nonzero) const {
  Eigen::MatrixXd out(rows(), x.cols());
  for (size_t g = 0; g < groups.size(); ++g) {
    out.middleRows(group_first[g], groups[g]->values.cols()) = groups[g]->transpose_times(x, nonzero);
  }
  return out;
}

void ConstraintBlock::add_times(const Eigen::VectorXd& c, Eigen::VectorXd& out) const {
  for (size_t g = 0; g < groups.size(); ++g) groups[g]->add_times(c.segment(group_first[g], groups[g]->values.cols()), out);
}

std::shared_ptr<const ConstraintBlock> empty_block(const Factorization& factor) {
  auto block = std::make_shared<ConstraintBlock>();
  block->factor_id = factor.id();
  const auto nq = static_cast<Eigen::Index>(factor.pinned().size());
  block->l.resize(0, 0);
  block->s_kc.resize(0, nq);
  block->w.resize(0, nq);
  block->a_cc = factor.pin_block();
  block->t = block->a_cc;
  block->bytes = sizeof(ConstraintBlock) + static_cast<size_t>(2 * nq * nq) * sizeof(double);
  return block;
}

std::shared_ptr<const ConstraintBlock> extend_block(const Factorization& factor, const ConstraintBlock& parent,
                                                   std::vector<Terms> rows, std::vector<uint64_t> hashes,
                                                   uint64_t group_key) {
  const auto nq = static_cast<Eigen::Index>(factor.pinned().size());
  const Eigen::Index np = parent.rows(), ne = static_cast<Eigen::Index>(rows.size());
  Eigen::MatrixXd columns, on_pins;
  row_columns(factor, rows, &columns, on_pins);
  const Eigen::MatrixXd y = factor.forward(columns);
  auto swept = std::make_shared<const SweptColumns>(SweptColumns::compress(y));
  std::vector<char> reached(static_cast<size_t>(y.rows()), 0);
  for (int32_t row : swept->rows) reached[static_cast<size_t>(row)] = 1;
  // N and S between the new rows and everything before them (on the rows the new ones reach).
  const Eigen::MatrixXd cross = np ? parent.transpose_times(y, &reached) : Eigen::MatrixXd(0, ne);  // N(parent, new)
  const Eigen::MatrixXd n_new = swept->values.transpose() * swept->values;                          // N(new, new)
  Eigen::MatrixXd s_pin = on_pins;                                                                   // S(pins, new)
  if (nq > 0) s_pin.noalias() -= swept->transpose_times(factor.pin_columns()).transpose();

  auto block = std::make_shared<ConstraintBlock>();
  block->factor_id = factor.id();
  block->group_keys = parent.group_keys;
  block->group_keys.push_back(group_key);
  block->key = 0;
  for (uint64_t k : block->group_keys) block->key = mix(block->key, k);
  block->terms = parent.terms;
  block->hashes = parent.hashes;
  block->terms.insert(block->terms.end(), std::make_move_iterator(rows.begin()), std::make_move_iterator(rows.end()));
  block->hashes.insert(block->hashes.end(), hashes.begin(), hashes.end());
  block->groups = parent.groups;
  block->group_first = parent.group_first;
  block->groups.push_back(std::move(swept));
  block->group_first.push_back(static_cast<int32_t>(np));

  // Extend the Cholesky factor of N over the kept rows, one new row at a time.
  std::vector<int32_t> kept = parent.kept, deferred = parent.deferred;
  const auto nk0 = static_cast<Eigen::Index>(kept.size());
  Eigen::MatrixXd l = Eigen::MatrixXd::Zero(nk0 + ne, nk0 + ne);
  l.topLeftCorner(nk0, nk0) = parent.l;
  Eigen::Index nk = nk0;
  // N(kept row k, new row e): a parent row from `cross`, a new one from `n_new`.
  auto n_with = [&](int32_t block_row, Eigen::Index e) {
    return block_row < np ? cross(block_row, e) : n_new(block_row - np, e);
  };
  for (Eigen::Index e = 0; e < ne; ++e) {
    const double diagonal = n_new(e, e);
    Eigen::VectorXd v(nk);
    for (Eigen::Index k = 0; k < nk; ++k) v[k] = n_with(kept[static_cast<size_t>(k)], e);
    solve_lower_in_place(l.topLeftCorner(nk, nk), v);
    const double pivot = diagonal - v.squaredNorm();
    if (diagonal > 0.0 && pivot > kDeferPivot * diagonal) {
      l.block(nk, 0, 1, nk) = v.transpose();
      l(nk, nk) = std::sqrt(pivot);
      kept.push_back(static_cast<int32_t>(np + e));
      ++nk;
    } else {
      deferred.push_back(static_cast<int32_t>(np + e));
    }
  }
  block->l = l.topLeftCorner(nk, nk);
  block->kept = std::move(kept);
  block->deferred = std::move(deferred);

  // S(kept, core) and S(core, core); core = pins, then deferred rows. S between rows is -N.
  const auto nd0 = static_cast<Eigen::Index>(parent.deferred.size());
  const Eigen::Index nc = nq + static_cast<Eigen::Index>(block->deferred.size());
  // S between two block rows of which at least one is new.
  auto s_rows = [&](int32_t a, int32_t b) {
    if (a < np) return -cross(a, b - np);
    if (b < np) return -cross(b, a - np);
    return -n_new(a - np, b - np);
  };
  block->s_kc = Eigen::MatrixXd::Zero(nk, nc);
  block->s_kc.topLeftCorner(nk0, nq + nd0) = parent.s_kc;
  block->a_cc = Eigen::MatrixXd::Zero(nc, nc);
  block->a_cc.topLeftCorner(nq + nd0, nq + nd0) = parent.a_cc;
  auto is_old = [&](Eigen::Index core) { return core < nq + nd0; };  // a pin or a parent's deferred row
  auto core_row = [&](Eigen::Index core) { return block->deferred[static_cast<size_t>(core - nq)]; };
  for (Eigen::Index c = 0; c < nc; ++c) {
    for (Eigen::Index k = 0; k < nk; ++k) {
      const int32_t kr = block->kept[static_cast<size_t>(k)];
      if (kr < np && is_old(c)) continue;  // the parent's
      block->s_kc(k, c) = c < nq ? s_pin(c, kr - np) : s_rows(kr, core_row(c));
    }
    for (Eigen::Index c2 = 0; c2 <= c; ++c2) {
      if (is_old(c) && is_old(c2)) continue;  // the parent's (pins with pins: the factor's pin block)
      const double value = c2 < nq ? s_pin(c2, core_row(c) - np) : s_rows(core_row(c), core_row(c2));
      block->a_cc(c, c2) = block->a_cc(c2, c) = value;
    }
  }
  block->w = block->s_kc;
  solve_lower_in_place(block->l, block->w);
  block->t = block->a_cc;
  block->t.noalias() += block->w.transpose() * block->w;
  block->bytes = sizeof(ConstraintBlock) + block->groups.back()->bytes() +
                 static_cast<size_t>(block->l.size() + block->s_kc.size() + block->a_cc.size() + block->w.size() +
                                     block->t.size()) *
                     sizeof(double) +
                 block->hashes.size() * (sizeof(uint64_t) + sizeof(Terms) + 2 * sizeof(int32_t));
  for (const Terms& t : block->terms) block->bytes += t.size() * sizeof(Terms::value_type);
  // The parent's groups are shared, but a block can outlive its parent: count them too.
  for (size_t g = 0; g + 1 < block->groups.size(); ++g) block->bytes += block->groups[g]->bytes();
  return block;
}

SchurSystem::SchurSystem(const Factorization& factor, std::shared_ptr<const ConstraintBlock> block,
                         const std::vector<Terms>& new_rows, Eigen::MatrixXd new_columns)
    : factor_(factor), block_(std::move(block)), y_new_(std::move(new_columns)) {
  nq_ = static_cast<Eigen::Index>(factor.pinned().size());
  ng_ = static_cast<Eigen::Index>(new_rows.size());
  const ConstraintBlock& b = *block_;
  const auto nk = static_cast<Eigen::Index>(b.kept.size());
  const Eigen::Index nc = nq_ + static_cast<Eigen::Index>(b.deferred.size());
  // S(., G): pins M_QG - Y_Q^T Y_G, block rows -Y_B^T Y_G, new rows -Y_G^T Y_G.
  Eigen::MatrixXd on_pins;
  row_columns(factor, new_rows, nullptr, on_pins);
  Eigen::MatrixXd s_qg = on_pins;
  s_qg.noalias() -= factor.pin_columns().transpose() * y_new_;
  // The new rows are local: only the factor rows their sweep reached take part.
  std::vector<char> reached(static_cast<size_t>(y_new_.rows()), 0);
  for (Eigen::Index i = 0; i < y_new_.rows(); ++i) reached[static_cast<size_t>(i)] = !y_new_.row(i).isZero(0.0);
  const Eigen::MatrixXd cross = b.rows() ? b.transpose_times(y_new_, &reached) : Eigen::MatrixXd(0, ng_);
  Eigen::MatrixXd s_kg(nk, ng_), s_cg(nc, ng_);
  for (Eigen::Index k = 0; k < nk; ++k) s_kg.row(k) = -cross.row(b.kept[static_cast<size_t>(k)]);
  s_cg.topRows(nq_) = s_qg;
  for (size_t d = 0; d < b.deferred.size(); ++d) s_cg.row(nq_ + static_cast<Eigen::Index>(d)) = -cross.row(b.deferred[d]);
  w_new_ = s_kg;
  solve_lower_in_place(b.l, w_new_);

  Eigen::MatrixXd t(nc + ng_, nc + ng_);
  t.topLeftCorner(nc, nc) = b.t;
  t.topRightCorner(nc, ng_) = s_cg;
  t.topRightCorner(nc, ng_).noalias() += b.w.transpose() * w_new_;
  t.bottomRightCorner(ng_, ng_).noalias() = -y_new_.transpose() * y_new_;
  t.bottomRightCorner(ng_, ng_).noalias() += w_new_.transpose() * w_new_;
  t.bottomLeftCorner(ng_, nc) = t.topRightCorner(nc, ng_).transpose();
  // Symmetric diagonal scaling (pins carry stiffness, rows coefficients), then the decomposition.
  scale_.resize(t.rows());
  for (Eigen::Index i = 0; i < t.rows(); ++i) {
    const double diagonal = std::abs(t(i, i));
    const double magnitude = diagonal > 0.0 ? diagonal : t.row(i).cwiseAbs().maxCoeff();
    scale_[i] = magnitude > 0.0 ? 1.0 / std::sqrt(magnitude) : 1.0;
  }
  if (t.rows() > 0) {
    reduced_.setThreshold(1e-11);
    reduced_.compute(scale_.asDiagonal() * t * scale_.asDiagonal());
  }
}

Eigen::VectorXd SchurSystem::solve(const Eigen::VectorXd& r) const {
  const ConstraintBlock& b = *block_;
  const Eigen::Index nb = b.rows();
  const auto nk = static_cast<Eigen::Index>(b.kept.size());
  const Eigen::Index nc = nq_ + static_cast<Eigen::Index>(b.deferred.size());
  Eigen::VectorXd r_kept(nk), rhs(nc + ng_);
  for (Eigen::Index k = 0; k < nk; ++k) r_kept[k] = r[nq_ + b.kept[static_cast<size_t>(k)]];
  rhs.head(nq_) = r.head(nq_);
  for (size_t d = 0; d < b.deferred.size(); ++d) rhs[nq_ + static_cast<Eigen::Index>(d)] = r[nq_ + b.deferred[d]];
  rhs.tail(ng_) = r.tail(ng_);
  Eigen::VectorXd w_r = r_kept;
  solve_lower_in_place(b.l, w_r);
  rhs.head(nc).noalias() += b.w.transpose() * w_r;
  rhs.tail(ng_).noalias() += w_new_.transpose() * w_r;
  Eigen::VectorXd x = rhs.size() ? Eigen::VectorXd(scale_.asDiagonal() * reduced_.solve(scale_.asDiagonal() * rhs))
                                 : Eigen::VectorXd(0);
  // Back-substitution of the kept rows: y_k = L^-T (w y_core + W_G y_G - w_r).
  Eigen::VectorXd y_kept = -w_r;
  y_kept.noalias() += b.w * x.head(nc);
  y_kept.noalias() += w_new_ * x.tail(ng_);
  if (nk && y_kept.size()) b.l.transpose().triangularView<Eigen::Upper>().solveInPlace(y_kept);
  Eigen::VectorXd y(nq_ + nb + ng_);
  y.head(nq_) = x.head(nq_);
  for (size_t d = 0; d < b.deferred.size(); ++d) y[nq_ + b.deferred[d]] = x[nq_ + static_cast<Eigen::Index>(d)];
  for (Eigen::Index k = 0; k < nk; ++k) y[nq_ + b.kept[static_cast<size_t>(k)]] = y_kept[k];
  y.tail(ng_) = x.tail(ng_);
  return y;
}

Eigen::VectorXd SchurSystem::transpose_times(const Eigen::VectorXd& z) const {
  const Eigen::Index nb = block_->rows();
  Eigen::VectorXd out(nq_ + nb + ng_);
  out.head(nq_).noalias() = factor_.pin_columns().transpose() * z;
  if (nb) out.segment(nq_, nb) = block_->transpose_times(z);
  out.tail(ng_).noalias() = y_new_.transpose() * z;
  return out;
}

Eigen::VectorXd SchurSystem::times(const Eigen::VectorXd& y) const {
  const Eigen::Index nb = block_->rows();
  Eigen::VectorXd out = factor_.pin_columns() * y.head(nq_);
  if (nb) block_->add_times(y.segment(nq_, nb), out);
  out.noalias() += y_new_ * y.tail(ng_);
  return out;
}

}  // namespace softshell::engine::internal
