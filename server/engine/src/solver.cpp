#include "softshell/engine/solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <unordered_map>

#include <Eigen/Dense>
#include <Eigen/SparseLU>

#include "constraint_blocks.h"
#include "factor_cache_impl.h"
#include "factorization.h"
#include "problem.h"
#include "solver_testing.h"

namespace softshell::engine {

namespace internal {
std::atomic<FastPathCorruption> g_corrupt_fast_path{nullptr};
}  // namespace internal

using internal::ConstraintBlock;
using internal::Factorization;
using internal::Problem;
using internal::Row;
using internal::Terms;

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

// Extra prescribed DOFs that may be added as constraint rows to a cached factor instead of
// factorizing again. Each costs one more right-hand side in the triangular solves.
constexpr size_t kMaxExtraRows = 96;

// ------------------------------------------------------------------------------------------------
// The final check of every answer.
//
// Equilibrium: on every DOF that is not prescribed, r = f - K u - C^T lambda against
// kEquilibrium times the problem's force scale (the largest load, reaction or internal force).
// Constraints: C u - d within check_row's allowance (problem.h: a share of the displacements,
// of the object's size and of the round-off of the row's terms; a floor that holds an object
// where it is asks for displacements of ~1e-13 that contradict each other at round-off). Each
// equilibrium residual is also allowed kRoundOff of the sum of the magnitudes of its terms. The
// path's answer passes if every ratio residual / allowance is <= 1; the fast path refines until
// it is <= kConverged.
constexpr double kEquilibrium = 1e-8;
constexpr double kConverged = 1e-3;

struct Verdict {
  double worst = 0.0;       // the largest residual / allowance
  bool constraint = false;  // whether the worst is a constraint (else equilibrium)
  size_t row = 0;           // its row of the problem
  int32_t dof = -1;         // or its DOF
  double residual = 0.0, scale = 0.0;
  bool finite = true;
};

// The size of an object for the check: its bounding diagonal or its distance from the origin,
// whichever is larger (coordinates carry round-off of their magnitude).
double geometry_size(const ShellModel& model) {
  Vec3 lo, hi;
  model.mesh().bounding_box(lo, hi);
  return std::max({(hi - lo).norm(), lo.cwiseAbs().maxCoeff(), hi.cwiseAbs().maxCoeff()});
}

// `ku` = K u. `lambda`: the multiplier of every row of p. `size`: geometry_size(model).
Verdict judge(const ShellModel& model, const Problem& p, const Eigen::VectorXd& u, const Eigen::VectorXd& ku,
              const Eigen::VectorXd& lambda, double size) {
  Verdict v;
  if (!u.allFinite() || !lambda.allFinite()) {
    v.finite = false;
    v.worst = std::numeric_limits<double>::infinity();
    return v;
  }
  const Eigen::SparseMatrix<double>& k = model.stiffness();
  const Eigen::Index n = u.size();
  Eigen::VectorXd reaction = Eigen::VectorXd::Zero(n), reaction_size = Eigen::VectorXd::Zero(n);
  for (size_t r = 0; r < p.rows.size(); ++r) {
    const double l = lambda[static_cast<Eigen::Index>(r)];
    for (const auto& [dof, coef] : p.rows[r].terms) {
      reaction[dof] += coef * l;
      reaction_size[dof] += std::abs(coef * l);
    }
  }
  const double force_scale = std::max({p.load.cwiseAbs().maxCoeff(), ku.cwiseAbs().maxCoeff(),
                                       reaction.cwiseAbs().maxCoeff(), std::numeric_limits<double>::min()});
  for (Eigen::Index i = 0; i < n; ++i) {
    if (p.is_fixed[static_cast<size_t>(i)]) continue;
    const double residual = std::abs(p.load[i] - ku[i] - reaction[i]);
    double allowed = kEquilibrium * force_scale;
    if (residual > kConverged * allowed) {  // add the round-off of this row (K is symmetric: column i)
      double terms = std::abs(p.load[i]) + reaction_size[i];
      for (Eigen::SparseMatrix<double>::InnerIterator it(k, i); it; ++it) terms += std::abs(it.value() * u[it.row()]);
      allowed += internal::kRoundOff * terms;
    }
    if (residual > v.worst * allowed) {
      v = Verdict{residual / allowed, false, 0, static_cast<int32_t>(i), residual, force_scale, true};
    }
  }
  double displacement_scale = u.cwiseAbs().maxCoeff();
  for (int32_t dof : p.fixed) displacement_scale = std::max(displacement_scale, std::abs(p.fixed_value[dof]));
  for (const Row& row : p.rows) displacement_scale = std::max(displacement_scale, std::abs(row.rhs) / row.scale);
  for (size_t r = 0; r < p.rows.size(); ++r) {
    const auto [residual, allowed] = check_row(p.rows[r], u, displacement_scale, size);
    if (residual > v.worst * allowed) v = Verdict{residual / allowed, true, r, -1, residual, displacement_scale, true};
  }
  return v;
}

// ------------------------------------------------------------------------------------------------

// An answer of one path, with its check.
struct Answer {
  Eigen::VectorXd u, lambda;  // lambda per row of the problem
  SolveStats stats;
  Verdict verdict;
  std::vector<char> dependent;  // per row: dropped as dependent by the robust path
};

// The constraint block of a solve: the cached block on the factor with the most of its rows
// (found by the hashes of their coefficients, then compared), extended by the rows worth keeping:
// those the caller names as repeating, and those that were in the previous solve on this factor
// (in groups by how long they have been there, oldest first). Each extension is cached.
struct BlockChoice {
  std::shared_ptr<const ConstraintBlock> block;
  std::vector<int32_t> row_of;  // block row -> row of the solve
  int32_t reused = 0, cached = 0;
};

BlockChoice choose_block(FactorCache::Impl& cache, const Factorization& factor, const Problem& p,
                         const std::vector<Terms>& terms, const SolveOptions& options) {
  const size_t nr = terms.size();
  std::vector<uint64_t> hashes(nr);
  std::unordered_map<uint64_t, int32_t> first_with(nr);
  for (size_t r = 0; r < nr; ++r) {
    hashes[r] = internal::hash_terms(terms[r]);
    first_with.emplace(hashes[r], static_cast<int32_t>(r));
  }
  BlockChoice out;
  out.block = cache.find_block(factor.id(), first_with);
  if (out.block) {
    for (Eigen::Index b = 0; b < out.block->rows(); ++b) {
      const int32_t r = first_with.at(out.block->hashes[static_cast<size_t>(b)]);
      if (terms[static_cast<size_t>(r)] != out.block->terms[static_cast<size_t>(b)]) {  // a hash collision
        out.block = nullptr;
        out.row_of.clear();
        break;
      }
      out.row_of.push_back(r);
    }
  }
  if (!out.block) out.block = internal::empty_block(factor);
  out.reused = static_cast<int32_t>(out.block->rows());

  std::vector<uint64_t> since;
  const uint64_t now = cache.record_rows(factor.id(), hashes, since);
  std::vector<char> taken(nr, 0);
  for (int32_t r : out.row_of) taken[static_cast<size_t>(r)] = 1;
  for (size_t r = 0; r < nr; ++r) {
    if (first_with.at(hashes[r]) != static_cast<int32_t>(r)) taken[r] = 1;  // a duplicate stays new
  }
  std::vector<std::vector<int32_t>> groups;
  for (const ConstraintGroup& g : options.repeated) {
    std::vector<int32_t> group;
    for (size_t r = 0; r < p.rows.size(); ++r) {
      const Row& row = p.rows[r];
      const bool inside = (row.limit >= 0 && static_cast<size_t>(row.limit) >= g.first_limit &&
                           static_cast<size_t>(row.limit) < g.first_limit + g.limit_count) ||
                          (row.lagrange >= 0 && static_cast<size_t>(row.lagrange) >= g.first_lagrange &&
                           static_cast<size_t>(row.lagrange) < g.first_lagrange + g.lagrange_count);
      if (inside && !taken[r]) {
        group.push_back(static_cast<int32_t>(r));
        taken[r] = 1;
      }
    }
    if (!group.empty()) groups.push_back(std::move(group));
  }
  std::map<uint64_t, std::vector<int32_t>> by_age;
  for (size_t r = 0; r < nr; ++r) {
    if (!taken[r] && since[r] < now) by_age[since[r]].push_back(static_cast<int32_t>(r));
  }
  for (auto& [age, group] : by_age) groups.push_back(std::move(group));

  for (std::vector<int32_t>& group : groups) {
    // In the order of their hashes: the same rows make the same block whatever the request's order.
    std::sort(group.begin(), group.end(),
              [&](int32_t a, int32_t b) { return hashes[static_cast<size_t>(a)] < hashes[static_cast<size_t>(b)]; });
    std::vector<Terms> group_terms;
    std::vector<uint64_t> group_hashes;
    uint64_t key = 0x6a09e667f3bcc909ULL;
    for (int32_t r : group) {
      group_terms.push_back(terms[static_cast<size_t>(r)]);
      group_hashes.push_back(hashes[static_cast<size_t>(r)]);
      key = internal::hash_mix(key, hashes[static_cast<size_t>(r)]);
    }
    out.block = internal::extend_block(factor, *out.block, std::move(group_terms), std::move(group_hashes), key);
    cache.insert_block(out.block);
    out.row_of.insert(out.row_of.end(), group.begin(), group.end());
    out.cached += static_cast<int32_t>(group.size());
  }
  return out;
}

// The fast path: a cached factor with the fixed DOFs eliminated, pins for the free zero-energy
// motions, and the rows by a Schur complement on a (cached) constraint block plus the new rows.
Answer fast_path(const ShellModel& model, FactorCache& cache_interface, const Problem& p, const SolveOptions& options,
                 double size) {
  FactorCache::Impl& cache = internal::FactorCacheAccess::impl(cache_interface);
  Answer answer;
  SolveStats& stats = answer.stats;
  stats.path = SolvePath::kCachedFactor;

  // A cached factor whose prescribed DOFs are a subset of ours; the rest become rows.
  bool hit = true;
  std::shared_ptr<const Factorization> factor = cache.find_subset(model.id(), p.fixed, kMaxExtraRows);
  if (!factor) {
    factor = cache.get(model.id(), p.fixed,
                       [&] {
                         const internal::Pins pins = internal::choose_pins(model, p.fixed);
                         return std::make_shared<const Factorization>(model, p.fixed, pins.dofs, pins.motions);
                       },
                       hit);
  }
  stats.factor_cache_hit = hit;
  stats.factor_ms = hit ? 0.0 : factor->factor_ms();

  // All rows of this solve: the problem's, then prescribed DOFs the factor does not eliminate.
  // Rows were reduced with the request's prescribed values; the extra ones re-impose them, so
  // terms on DOFs the factor eliminates never appear.
  std::vector<Terms> terms;
  std::vector<double> rhs;
  for (const Row& row : p.rows) {
    terms.push_back(row.terms);
    rhs.push_back(row.rhs);
  }
  {
    std::vector<int32_t> extra;
    std::set_difference(p.fixed.begin(), p.fixed.end(), factor->fixed().begin(), factor->fixed().end(),
                        std::back_inserter(extra));
    for (int32_t dof : extra) {
      terms.push_back({{dof, 1.0}});
      rhs.push_back(p.fixed_value[dof]);
    }
  }
  const size_t nr = terms.size();
  stats.constraint_rows = static_cast<int32_t>(nr);

  // The block of this solve: what is cached of these rows, extended by the rows worth keeping;
  // the other rows are new.
  const BlockChoice chosen = choose_block(cache, *factor, p, terms, options);
  const std::shared_ptr<const ConstraintBlock>& block = chosen.block;
  const std::vector<int32_t>& block_row_of = chosen.row_of;
  stats.reused_rows = chosen.reused;
  stats.cached_rows = chosen.cached;
  std::vector<int32_t> new_rows;  // rows of this solve outside the block
  {
    std::vector<char> in_block(nr, 0);
    for (int32_t r : block_row_of) in_block[static_cast<size_t>(r)] = 1;
    for (size_t r = 0; r < nr; ++r) {
      if (!in_block[r]) new_rows.push_back(static_cast<int32_t>(r));
    }
  }

  // Right-hand side of the factored DOFs: loads minus the pull of the factor's prescribed DOFs
  // (only those prescribed to move pull; K is symmetric, so column j is row j).
  const Eigen::SparseMatrix<double>& k = model.stiffness();
  Eigen::VectorXd b = p.load;
  Eigen::VectorXd u = Eigen::VectorXd::Zero(model.num_dofs());
  for (int32_t dof : factor->fixed()) {
    const double value = p.fixed_value[dof];
    if (value == 0.0) continue;
    u[dof] = value;
    for (Eigen::SparseMatrix<double>::InnerIterator it(k, dof); it; ++it) b[it.row()] -= it.value() * value;
  }
  const std::vector<int32_t>& factored = factor->factored();
  const std::vector<int32_t>& pins = factor->pinned();
  const auto na = static_cast<Eigen::Index>(factored.size());
  const auto nq = static_cast<Eigen::Index>(pins.size());
  const auto nb = block->rows();
  const auto ng = static_cast<Eigen::Index>(new_rows.size());

  // One forward sweep of [b_a | C_G^T] (only the part of the factor they reach), the small
  // system on the block and the new rows, and one backward sweep: about the cost of one solve.
  // (Without loads or prescribed motions b_a is zero, and so is its column.)
  Eigen::VectorXd b_a(na);
  for (Eigen::Index i = 0; i < na; ++i) b_a[i] = b[factored[static_cast<size_t>(i)]];
  const bool loaded = !b_a.isZero(0.0);
  const Eigen::Index first = loaded ? 1 : 0;
  Eigen::MatrixXd sweep = Eigen::MatrixXd::Zero(na, first + ng);
  if (loaded) sweep.col(0) = b_a;
  std::vector<Terms> new_terms;
  for (Eigen::Index g = 0; g < ng; ++g) {
    new_terms.push_back(terms[static_cast<size_t>(new_rows[static_cast<size_t>(g)])]);
    for (const auto& [dof, coef] : new_terms.back()) {
      if (const int32_t a = factor->position(dof); a >= 0) sweep(a, first + g) += coef;
    }
  }
  Eigen::MatrixXd forward = factor->forward(sweep, &stats.forward_fraction);
  const Eigen::VectorXd y_b = loaded ? Eigen::VectorXd(forward.col(0)) : Eigen::VectorXd::Zero(na);
  const internal::SchurSystem system(*factor, block, new_terms, forward.rightCols(ng));
  forward.resize(0, 0);

  // Unknowns of the small system: [pins | block rows | new rows]; `row_of` maps the last two.
  std::vector<int32_t> row_of(block_row_of);
  row_of.insert(row_of.end(), new_rows.begin(), new_rows.end());
  Eigen::VectorXd r_small(nq + nb + ng);
  for (Eigen::Index q = 0; q < nq; ++q) r_small[q] = b[pins[static_cast<size_t>(q)]];
  for (size_t i = 0; i < row_of.size(); ++i) r_small[nq + static_cast<Eigen::Index>(i)] = rhs[static_cast<size_t>(row_of[i])];
  if (loaded) r_small -= system.transpose_times(y_b);
  Eigen::VectorXd y = system.solve(r_small);
  Eigen::VectorXd u_a = factor->backward(y_b - system.times(y));

  auto scatter = [&] {
    for (Eigen::Index i = 0; i < na; ++i) u[factored[static_cast<size_t>(i)]] = u_a[i];
    for (Eigen::Index q = 0; q < nq; ++q) u[pins[static_cast<size_t>(q)]] = y[q];
    for (int32_t dof : p.fixed) u[dof] = p.fixed_value[dof];
  };
  auto multipliers = [&] {  // per row of the problem
    Eigen::VectorXd lambda = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(p.rows.size()));
    for (size_t i = 0; i < row_of.size(); ++i) {
      if (static_cast<size_t>(row_of[i]) < p.rows.size()) lambda[row_of[i]] = y[nq + static_cast<Eigen::Index>(i)];
    }
    return lambda;
  };
  scatter();

  // Check, and refine against the full system's residual while it is not at round-off (each
  // step costs one more pair of sweeps).
  Eigen::VectorXd ku = k * u;
  answer.verdict = judge(model, p, u, ku, multipliers(), size);
  for (int step = 0; step < 3 && answer.verdict.finite && answer.verdict.worst > kConverged; ++step) {
    Eigen::VectorXd force = p.load - ku;
    for (size_t i = 0; i < row_of.size(); ++i) {
      for (const auto& [dof, coef] : terms[static_cast<size_t>(row_of[i])]) force[dof] -= coef * y[nq + static_cast<Eigen::Index>(i)];
    }
    Eigen::VectorXd res_a(na), res_small(nq + nb + ng);
    for (Eigen::Index i = 0; i < na; ++i) res_a[i] = force[factored[static_cast<size_t>(i)]];
    for (Eigen::Index q = 0; q < nq; ++q) res_small[q] = force[pins[static_cast<size_t>(q)]];
    for (size_t i = 0; i < row_of.size(); ++i) {
      const auto r = static_cast<size_t>(row_of[i]);
      double lhs = 0.0;
      for (const auto& [dof, coef] : terms[r]) lhs += coef * u[dof];
      res_small[nq + static_cast<Eigen::Index>(i)] = rhs[r] - lhs;
    }
    const Eigen::VectorXd z = factor->forward(res_a);
    const Eigen::VectorXd dy = system.solve(res_small - system.transpose_times(z));
    u_a += factor->backward(z - system.times(dy));
    y += dy;
    scatter();
    ku = k * u;
    answer.verdict = judge(model, p, u, ku, multipliers(), size);
    ++stats.refinement_steps;
  }
  if (const internal::FastPathCorruption corrupt = internal::g_corrupt_fast_path.load()) {
    corrupt(u);
    answer.verdict = judge(model, p, u, k * u, multipliers(), size);
  }
  answer.lambda = multipliers();
  answer.u = std::move(u);
  return answer;
}

// The robust path: sparse LU of the full KKT system (independent rows only; the dependent ones
// are checked afterwards).
Answer robust_path(const ShellModel& model, const Problem& p, double size) {
  Answer answer;
  const int32_t ndof = model.num_dofs();
  std::vector<int32_t> index(static_cast<size_t>(ndof), -1);
  std::vector<int32_t> free_dofs;
  for (int32_t d = 0; d < ndof; ++d) {
    if (!p.is_fixed[static_cast<size_t>(d)]) {
      index[static_cast<size_t>(d)] = static_cast<int32_t>(free_dofs.size());
      free_dofs.push_back(d);
    }
  }
  const auto nf = static_cast<Eigen::Index>(free_dofs.size());
  const Eigen::SparseMatrix<double>& k = model.stiffness();
  Eigen::VectorXd u_fixed = Eigen::VectorXd::Zero(ndof);
  for (int32_t dof : p.fixed) u_fixed[dof] = p.fixed_value[dof];
  const Eigen::VectorXd b = p.load - k * u_fixed;

  // Independent rows only, scaled to K's magnitude.
  std::vector<size_t> independent;
  answer.dependent.assign(p.rows.size(), 1);
  if (!p.rows.empty()) {
    Eigen::MatrixXd ct = Eigen::MatrixXd::Zero(nf, static_cast<Eigen::Index>(p.rows.size()));
    for (size_t r = 0; r < p.rows.size(); ++r) {
      for (const auto& [dof, coef] : p.rows[r].terms) {
        ct(index[static_cast<size_t>(dof)], static_cast<Eigen::Index>(r)) = coef / p.rows[r].scale;
      }
    }
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(ct);
    qr.setThreshold(1e-10);
    for (Eigen::Index i = 0; i < qr.rank(); ++i) independent.push_back(static_cast<size_t>(qr.colsPermutation().indices()[i]));
    std::sort(independent.begin(), independent.end());
    for (size_t r : independent) answer.dependent[r] = 0;
  }
  double k_scale = 0.0;
  for (int32_t d : free_dofs) k_scale = std::max(k_scale, std::abs(k.coeff(d, d)));
  if (k_scale <= 0.0) k_scale = 1.0;

  const auto nc = static_cast<Eigen::Index>(independent.size());
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(static_cast<size_t>(k.nonZeros()));
  for (int32_t col : free_dofs) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(k, col); it; ++it) {
      const int32_t row = index[static_cast<size_t>(it.row())];
      if (row >= 0) triplets.emplace_back(row, index[static_cast<size_t>(col)], it.value());
    }
  }
  Eigen::VectorXd rhs(nf + nc);
  for (Eigen::Index i = 0; i < nf; ++i) rhs[i] = b[free_dofs[static_cast<size_t>(i)]];
  std::vector<double> weight(static_cast<size_t>(nc));
  for (Eigen::Index c = 0; c < nc; ++c) {
    const Row& row = p.rows[independent[static_cast<size_t>(c)]];
    const double w = k_scale / row.scale;
    weight[static_cast<size_t>(c)] = w;
    for (const auto& [dof, coef] : row.terms) {
      triplets.emplace_back(nf + c, index[static_cast<size_t>(dof)], w * coef);
      triplets.emplace_back(index[static_cast<size_t>(dof)], nf + c, w * coef);
    }
    rhs[nf + c] = w * row.rhs;
  }
  Eigen::SparseMatrix<double> kkt(nf + nc, nf + nc);
  kkt.setFromTriplets(triplets.begin(), triplets.end());
  kkt.makeCompressed();
  Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::COLAMDOrdering<int>> lu;
  lu.compute(kkt);
  if (lu.info() != Eigen::Success) {
    fail(ErrorCode::kUnprocessable,
         "the system is singular: the constraints do not determine the deformation, or the control mesh has "
         "displacement modes that do not move its limit surface (a cube whose vertices all have valence 3 has "
         "one); subdividing the mesh once removes such modes");
  }
  const Eigen::VectorXd x = lu.solve(rhs);
  answer.u = u_fixed;
  for (Eigen::Index i = 0; i < nf; ++i) answer.u[free_dofs[static_cast<size_t>(i)]] = x[i];
  answer.lambda = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(p.rows.size()));
  for (Eigen::Index c = 0; c < nc; ++c) {
    answer.lambda[static_cast<Eigen::Index>(independent[static_cast<size_t>(c)])] = weight[static_cast<size_t>(c)] * x[nf + c];
  }
  answer.verdict = judge(model, p, answer.u, k * answer.u, answer.lambda, size);
  answer.stats.path = SolvePath::kFallback;
  answer.stats.constraint_rows = static_cast<int32_t>(nc);
  return answer;
}

std::string describe(const ShellModel& model, const Problem& p, const Verdict& v) {
  if (!v.finite) return "the solve did not give finite displacements";
  Vec3 lo, hi;
  model.mesh().bounding_box(lo, hi);
  if (v.constraint) {
    return p.rows[v.row].source + " is off by " + internal::format_number(v.residual) + " (displacements of " +
           internal::format_number(v.scale) + ", an object of size " + internal::format_number((hi - lo).norm()) + ")";
  }
  return "equilibrium at control point " + std::to_string(v.dof / 3) + " (" + internal::axis_name(v.dof % 3) +
         ") is off by " + internal::format_number(v.residual) + " (forces of " + internal::format_number(v.scale) + ")";
}

// The robust path's answer, or the reason there is none.
Answer checked_robust_path(const ShellModel& model, const Problem& p, const std::string& fast_failure, double size) {
  Answer answer = robust_path(model, p, size);
  const Verdict& v = answer.verdict;
  if (v.worst <= 1.0) return answer;
  if (v.finite && v.constraint && answer.dependent[v.row]) {
    fail(ErrorCode::kUnprocessable, "the constraints contradict each other: " + p.rows[v.row].source +
                                        " cannot be met together with the others: " + describe(model, p, v));
  }
  fail(ErrorCode::kUnprocessable,
       "no accurate answer: " + describe(model, p, v) +
           " after the robust solve" + (fast_failure.empty() ? std::string() : " (and the fast one: " + fast_failure + ")") +
           ". The system is too ill-conditioned for double precision; very thin shells with very stiff constraints "
           "are; check the thickness and the units");
}

Solution to_solution(Answer&& answer, Clock::time_point start) {
  Solution solution;
  solution.displacement = std::move(answer.u);
  solution.stats = answer.stats;
  solution.stats.check_ratio = answer.verdict.worst;
  solution.stats.solve_ms = ms_since(start);
  return solution;
}

}  // namespace

std::vector<Vec3> Solution::positions(const ControlMesh& mesh) const {
  std::vector<Vec3> out = mesh.positions();
  for (size_t i = 0; i < out.size(); ++i) out[i] += displacement.segment<3>(static_cast<Eigen::Index>(3 * i));
  return out;
}

Solver::Solver(std::shared_ptr<const ShellModel> model, std::shared_ptr<FactorCache> cache)
    : model_(std::move(model)), cache_(std::move(cache)) {
  if (!model_) fail(ErrorCode::kInvalidArgument, "Solver needs a model");
  if (!cache_) cache_ = std::make_shared<FactorCache>();
  size_ = geometry_size(*model_);
}

Result<Solution> Solver::solve(const DeformationRequest& request, const SolveOptions& options) const {
  return capture([&]() -> Solution {
    const auto start = Clock::now();
    Problem p = internal::build_problem(*model_, request);
    internal::check_determined(*model_, p);
    std::string fast_failure;
    try {
      Answer fast = fast_path(*model_, *cache_, p, options, size_);
      if (fast.verdict.worst <= 1.0) return to_solution(std::move(fast), start);
      fast_failure = describe(*model_, p, fast.verdict);
    } catch (const internal::FactorizationFailed& e) {
      // A mechanism (part of the shell moving without strain) that the zero-mode analysis did
      // not catch: the full KKT system tells whether the constraints hold it.
      (void)e;
    }
    Answer robust = checked_robust_path(*model_, p, fast_failure, size_);
    robust.stats.fast_path_rejected = !fast_failure.empty();
    return to_solution(std::move(robust), start);
  });
}

Result<Solution> Solver::solve_with_fallback(const DeformationRequest& request) const {
  return capture([&]() -> Solution {
    const auto start = Clock::now();
    Problem p = internal::build_problem(*model_, request);
    internal::check_determined(*model_, p);
    return to_solution(checked_robust_path(*model_, p, {}, size_), start);
  });
}

}  // namespace softshell::engine
