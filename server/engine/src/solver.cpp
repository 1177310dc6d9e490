#include "softshell/engine/solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>

#include <Eigen/Dense>
#include <Eigen/SparseLU>

#include "constraint_rows.h"
#include "factor_cache_impl.h"
#include "factorization.h"
#include "request_check.h"

namespace softshell::engine {

using internal::Factorization;

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

// Extra prescribed DOFs that may be added as constraint rows to a cached factor instead of
// factorizing again. Each costs one more right-hand side in the triangular solves.
constexpr size_t kMaxExtraRows = 96;

std::string format_number(double x) {
  std::ostringstream s;
  s.precision(3);
  s << x;
  return s.str();
}

std::string axis_name(int a) { return std::string(1, "xyz"[a]); }

std::string format_vec(Vec3 v) {
  // Round-off noise shown as 0 (and never as -0).
  const double top = v.cwiseAbs().maxCoeff();
  for (int i = 0; i < 3; ++i) v[i] = std::abs(v[i]) <= 1e-9 * top ? 0.0 : v[i];
  std::ostringstream s;
  s.precision(4);
  s << "(" << v.x() << ", " << v.y() << ", " << v.z() << ")";
  return s.str();
}

}  // namespace

// The request-to-rows part is shared with the nonlinear solver (constraint_rows.h).
namespace internal {

void add_row(Row row, std::vector<Row>& rows) {
  std::sort(row.terms.begin(), row.terms.end());
  std::vector<std::pair<int32_t, double>> merged;
  for (const auto& t : row.terms) {
    if (!merged.empty() && merged.back().first == t.first) {
      merged.back().second += t.second;
    } else {
      merged.push_back(t);
    }
  }
  row.terms.clear();
  for (const auto& t : merged) {
    if (t.second != 0.0) row.terms.push_back(t);
  }
  row.scale = 0.0;
  for (const auto& t : row.terms) row.scale = std::max(row.scale, std::abs(t.second));
  if (row.terms.empty()) {
    if (row.rhs == 0.0) return;  // 0 = 0: dropped (PROTOCOL.md)
    fail(ErrorCode::kUnprocessable, row.source + " has only zero coefficients but asks for the value " +
                                        std::to_string(row.rhs) + "; no displacement can satisfy it");
  }
  rows.push_back(std::move(row));
}

Problem build_problem(const ShellModel& model, const DeformationRequest& request) {
  internal::check_request(model, request);
  const int32_t ndof = model.num_dofs();
  Problem p;
  p.fixed_value = Eigen::VectorXd::Zero(ndof);
  p.is_fixed.assign(static_cast<size_t>(ndof), 0);
  std::vector<int32_t> fixed_by(static_cast<size_t>(ndof), -1);
  const double length = std::max(model.mesh().bounding_diagonal(), 1e-300);

  // Prescribed DOFs; the same DOF twice must agree.
  for (size_t i = 0; i < request.vertex_constraints.size(); ++i) {
    const VertexConstraint& c = request.vertex_constraints[i];
    for (int a = 0; a < 3; ++a) {
      if (!(c.mask & (1u << a))) continue;
      const int32_t dof = 3 * c.index + a;
      const double value = c.displacement[a];
      if (p.is_fixed[static_cast<size_t>(dof)]) {
        const double have = p.fixed_value[dof];
        if (std::abs(have - value) > 1e-9 * std::max({std::abs(have), std::abs(value), 1e-6 * length})) {
          fail(ErrorCode::kUnprocessable,
               "vertex constraints " + std::to_string(fixed_by[static_cast<size_t>(dof)]) + " and " + std::to_string(i) +
                   " prescribe different displacements for control point " + std::to_string(c.index) + " along " +
                   axis_name(a) + " (" + std::to_string(have) + " and " + std::to_string(value) + ")");
        }
        continue;
      }
      p.is_fixed[static_cast<size_t>(dof)] = 1;
      p.fixed_value[dof] = value;
      fixed_by[static_cast<size_t>(dof)] = static_cast<int32_t>(i);
      p.fixed.push_back(dof);
    }
  }
  std::sort(p.fixed.begin(), p.fixed.end());

  // Lagrange constraints: one equation per axis.
  std::vector<Row> rows;
  for (size_t i = 0; i < request.lagrange_constraints.size(); ++i) {
    const LagrangeConstraint& c = request.lagrange_constraints[i];
    for (int a = 0; a < 3; ++a) {
      Row row;
      row.source = "Lagrange constraint " + std::to_string(i) + " (" + axis_name(a) + ")";
      row.rhs = c.values[a];
      for (size_t k = 0; k < c.indices.size(); ++k) row.terms.push_back({3 * c.indices[k] + a, c.coefficients[k][a]});
      add_row(std::move(row), rows);
    }
  }
  // Limit constraints: position (and tangents) of the limit surface through its stencil.
  LimitStencil st;
  for (size_t i = 0; i < request.limit_constraints.size(); ++i) {
    const LimitConstraint& c = request.limit_constraints[i];
    model.evaluator().stencil(c.point, st);
    auto add = [&](const std::vector<double>& weights, const Vec3& target, const char* what) {
      for (int a = 0; a < 3; ++a) {
        Row row;
        row.source = "limit constraint " + std::to_string(i) + " (" + what + axis_name(a) + ")";
        row.rhs = target[a];
        for (size_t k = 0; k < st.size(); ++k) row.terms.push_back({3 * st.indices[k] + a, weights[k]});
        add_row(std::move(row), rows);
      }
    };
    add(st.position, c.displacement, "");
    if (c.du_displacement) add(st.du, *c.du_displacement, "du ");
    if (c.dv_displacement) add(st.dv, *c.dv_displacement, "dv ");
  }

  // Move prescribed DOFs to the right-hand side; rows left with nothing must already hold.
  for (Row& row : rows) {
    double moved = 0.0;
    std::vector<std::pair<int32_t, double>> free_terms;
    for (const auto& [dof, coef] : row.terms) {
      if (p.is_fixed[static_cast<size_t>(dof)]) {
        moved += coef * p.fixed_value[dof];
      } else {
        free_terms.push_back({dof, coef});
      }
    }
    const double original = row.rhs;
    row.rhs -= moved;
    row.terms = std::move(free_terms);
    if (row.terms.empty()) {
      if (std::abs(row.rhs) > 1e-9 * std::max({std::abs(original), std::abs(moved), 1e-9 * length})) {
        fail(ErrorCode::kUnprocessable, row.source +
                                            " contradicts the vertex constraints: every control point it depends on "
                                            "is prescribed, and their displacements do not satisfy it");
      }
      continue;
    }
    p.rows.push_back(std::move(row));
  }
  p.load = model.load_vector(request);
  return p;
}

// Zero-energy motions that the prescribed DOFs leave free: an orthonormal basis N of
// combinations of the model's zero-energy modes (rigid and extra) that vanish on every prescribed
// DOF. Modes of different components never overlap, so this is done one component at a time
// (a few modes each) instead of on all modes at once (an object of many parts has hundreds).
Eigen::MatrixXd free_rigid_combinations(const ShellModel& model, const std::vector<int32_t>& fixed) {
  const Eigen::MatrixXd& modes = model.zero_energy_modes();
  const std::vector<int32_t>& mode_component = model.zero_energy_mode_component();
  const std::vector<int32_t>& component_of = model.component_of();
  std::vector<std::vector<Eigen::Index>> component_modes(static_cast<size_t>(model.num_components()));
  for (Eigen::Index mode = 0; mode < modes.cols(); ++mode) {
    component_modes[static_cast<size_t>(mode_component[static_cast<size_t>(mode)])].push_back(mode);
  }
  std::vector<std::vector<int32_t>> component_fixed(component_modes.size());
  for (int32_t dof : fixed) component_fixed[static_cast<size_t>(component_of[static_cast<size_t>(dof / 3)])].push_back(dof);

  std::vector<Eigen::VectorXd> null;
  for (size_t c = 0; c < component_modes.size(); ++c) {
    const std::vector<Eigen::Index>& own = component_modes[c];
    const auto m = static_cast<Eigen::Index>(own.size());
    Eigen::MatrixXd gram = Eigen::MatrixXd::Zero(m, m);
    Eigen::RowVectorXd row(m);
    for (int32_t dof : component_fixed[c]) {
      for (Eigen::Index i = 0; i < m; ++i) row[i] = modes(dof, own[static_cast<size_t>(i)]);
      gram.noalias() += row.transpose() * row;
    }
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(gram);
    const double top = std::max(1.0, eig.eigenvalues().cwiseAbs().maxCoeff());
    for (Eigen::Index k = 0; k < m; ++k) {
      if (eig.eigenvalues()[k] > 1e-11 * top) continue;
      Eigen::VectorXd combination = Eigen::VectorXd::Zero(modes.cols());
      for (Eigen::Index i = 0; i < m; ++i) combination[own[static_cast<size_t>(i)]] = eig.eigenvectors()(i, k);
      null.push_back(std::move(combination));
    }
  }
  Eigen::MatrixXd basis(modes.cols(), static_cast<Eigen::Index>(null.size()));
  for (size_t k = 0; k < null.size(); ++k) basis.col(static_cast<Eigen::Index>(k)) = null[k];
  return basis;
}

// Describes a rigid motion given as a combination of the rigid modes, for error messages.
std::string describe_rigid_motion(const ShellModel& model, const Eigen::VectorXd& combination) {
  const Eigen::Index rigid = model.num_rigid_modes();
  Eigen::Index best = 0;
  for (Eigen::Index c = 0; c < rigid / 6; ++c) {
    if (combination.segment<6>(6 * c).norm() > combination.segment<6>(6 * best).norm()) best = c;
  }
  if (combination.size() > rigid && combination.tail(combination.size() - rigid).norm() > combination.segment<6>(6 * best).norm()) {
    Eigen::Index mode = 0;
    combination.tail(combination.size() - rigid).cwiseAbs().maxCoeff(&mode);
    Eigen::Index dof = 0;
    model.zero_energy_modes().col(rigid + mode).cwiseAbs().maxCoeff(&dof);
    return "the constraints leave a zero-energy mode of the control mesh free (it moves control point " +
           std::to_string(dof / 3) + " without straining the surface; small closed parts such as a cube whose "
           "vertices all have valence 3 have such modes). Hold that part with vertex constraints, or subdivide the "
           "mesh once";
  }
  // Centroid and size of that component (as in compute_rigid_modes).
  const auto& comp = model.component_of();
  Vec3 centre = Vec3::Zero();
  int count = 0;
  int32_t example = -1;
  for (size_t v = 0; v < comp.size(); ++v) {
    if (comp[v] != best) continue;
    centre += model.mesh().positions()[v];
    ++count;
    if (example < 0) example = static_cast<int32_t>(v);
  }
  centre /= std::max(count, 1);
  double size = 0.0;
  for (size_t v = 0; v < comp.size(); ++v) {
    if (comp[v] == best) size = std::max(size, (model.mesh().positions()[v] - centre).norm());
  }
  if (size <= 0.0) size = 1.0;
  const Vec3 t = combination.segment<3>(6 * best);
  const Vec3 w = combination.segment<3>(6 * best + 3) / size;
  std::string part = model.num_components() > 1
                         ? "part " + std::to_string(best) + " of the object (the one with control point " +
                               std::to_string(example) + ")"
                         : "the object";
  // Directions are reported with their largest component positive.
  auto direction = [](Vec3 v) {
    v.normalize();
    Eigen::Index largest = 0;
    v.cwiseAbs().maxCoeff(&largest);
    return v[largest] < 0.0 ? Vec3(-v) : v;
  };
  std::string motion;
  if (w.norm() * size < 1e-6 * t.norm()) {
    motion = "translate along " + format_vec(direction(t));
  } else {
    const Vec3 through = centre + w.cross(t) / w.squaredNorm();
    motion = "rotate about the axis along " + format_vec(direction(w)) + " through " + format_vec(through);
  }
  std::string mixed;
  if (combination.size() > rigid && combination.tail(combination.size() - rigid).norm() > 1e-6 * combination.norm()) {
    mixed = " (combined with a zero-energy mode of its control mesh)";
  }
  return "the constraints leave a rigid-body motion free: " + part + " can " + motion + mixed +
         " without any strain. Add vertex, Lagrange or limit constraints that hold it (a free body needs at least "
         "three non-collinear held points)";
}

// Throws kUnprocessable if the prescribed DOFs and the rows leave a zero-energy motion free.
// Free motions that do not move the limit surface (invisible control-mesh modes) are not an
// error: their amplitude is set to zero by adding a row, unless a load acts on them.
void check_determined(const ShellModel& model, Problem& p) {
  const Eigen::MatrixXd null = free_rigid_combinations(model, p.fixed);
  if (null.cols() == 0) return;
  const Eigen::MatrixXd& modes = model.zero_energy_modes();
  // Each row applied to each free motion.
  Eigen::MatrixXd seen = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(p.rows.size()), null.cols());
  for (size_t r = 0; r < p.rows.size(); ++r) {
    Eigen::RowVectorXd acc = Eigen::RowVectorXd::Zero(modes.cols());
    for (const auto& [dof, coef] : p.rows[r].terms) acc.noalias() += coef / p.rows[r].scale * modes.row(dof);
    seen.row(static_cast<Eigen::Index>(r)) = acc * null;
  }
  // The combinations no row holds: the right singular vectors of `seen` with (near) zero
  // singular values, and all of them when there are fewer rows than motions.
  Eigen::MatrixXd unheld;
  if (seen.rows() == 0) {
    unheld = null;
  } else {
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(seen, Eigen::ComputeFullV);
    const auto& s = svd.singularValues();
    Eigen::Index held = 0;
    while (held < s.size() && s[held] > 1e-8 * std::max(1.0, s[0])) ++held;
    if (held == null.cols()) return;
    unheld = null * svd.matrixV().rightCols(null.cols() - held);
  }
  const Eigen::Index rigid = model.num_rigid_modes();
  const auto& invisible = model.invisible_modes();
  for (Eigen::Index k = 0; k < unheld.cols(); ++k) {
    const Eigen::VectorXd combination = unheld.col(k);
    // Only invisible extra modes may be gauged away.
    double visible = combination.head(rigid).norm();
    for (size_t e = 0; e < invisible.size(); ++e) {
      if (!invisible[e]) visible += std::abs(combination[rigid + static_cast<Eigen::Index>(e)]);
    }
    if (visible > 1e-8 * combination.norm()) fail(ErrorCode::kUnprocessable, describe_rigid_motion(model, combination));
    const Eigen::VectorXd motion = modes * combination;
    if (std::abs(motion.dot(p.load)) > 1e-9 * motion.cwiseAbs().maxCoeff() * std::max(p.load.cwiseAbs().sum(), 1e-300)) {
      Eigen::Index dof = 0;
      motion.cwiseAbs().maxCoeff(&dof);
      fail(ErrorCode::kUnprocessable,
           "a force acts on a motion of the control mesh that does not move its limit surface (around control point " +
               std::to_string(dof / 3) + "); apply it as a surface force at (face, u, v) instead of on control points");
    }
    Row row;
    row.source = "gauge of an invisible control-mesh mode";
    for (Eigen::Index d = 0; d < motion.size(); ++d) {
      if (motion[d] != 0.0 && !p.is_fixed[static_cast<size_t>(d)]) row.terms.push_back({static_cast<int32_t>(d), motion[d]});
    }
    row.scale = motion.cwiseAbs().maxCoeff();
    p.rows.push_back(std::move(row));
  }
}

// Pins for a factorization with prescribed DOFs `fixed`: one DOF per free rigid motion, chosen
// by pivoted QR so that the rest of K is positive definite.
std::vector<int32_t> choose_pins(const ShellModel& model, const std::vector<int32_t>& fixed) {
  const Eigen::MatrixXd null = free_rigid_combinations(model, fixed);
  if (null.cols() == 0) return {};
  Eigen::MatrixXd motions = model.zero_energy_modes() * null;  // 3n x r
  for (int32_t dof : fixed) motions.row(dof).setZero();
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(motions.transpose());
  std::vector<int32_t> pins;
  for (Eigen::Index k = 0; k < null.cols(); ++k) pins.push_back(static_cast<int32_t>(qr.colsPermutation().indices()[k]));
  std::sort(pins.begin(), pins.end());
  return pins;
}

// Checks that the solution meets every row and is finite; kUnprocessable otherwise.
void check_solution(const Problem& p, const Eigen::VectorXd& u, double length) {
  if (!u.allFinite()) {
    fail(ErrorCode::kUnprocessable, "the system could not be solved to finite displacements (it is singular)");
  }
  const double scale = std::max(u.cwiseAbs().maxCoeff(), 1e-12 * length);
  for (const Row& row : p.rows) {
    double lhs = 0.0;
    for (const auto& [dof, coef] : row.terms) lhs += coef * u[dof];
    if (std::abs(lhs - row.rhs) > 1e-7 * row.scale * scale + 1e-12 * std::abs(row.rhs)) {
      fail(ErrorCode::kUnprocessable, "the constraints contradict each other: " + row.source +
                                          " (displacement scale " + format_number(scale) + ")" +
                                          " cannot be met together with the others (residual " +
                                          format_number(lhs - row.rhs) + ")");
    }
  }
}

}  // namespace internal

using internal::build_problem;
using internal::check_determined;
using internal::check_solution;
using internal::choose_pins;
using internal::Problem;
using internal::Row;
using internal::SmallSystem;

std::vector<Vec3> Solution::positions(const ControlMesh& mesh) const {
  std::vector<Vec3> out = mesh.positions();
  for (size_t i = 0; i < out.size(); ++i) out[i] += displacement.segment<3>(static_cast<Eigen::Index>(3 * i));
  return out;
}

Solver::Solver(std::shared_ptr<const ShellModel> model, std::shared_ptr<FactorCache> cache)
    : model_(std::move(model)), cache_(std::move(cache)) {
  if (!model_) fail(ErrorCode::kInvalidArgument, "Solver needs a model");
  if (!cache_) cache_ = std::make_shared<FactorCache>();
}

Result<Solution> Solver::solve(const DeformationRequest& request) const {
  try {
    return solve_on_cached_factor(request);
  } catch (const internal::FactorizationFailed&) {
    // A mechanism (part of the shell moving without strain) that the rigid-mode analysis did not
    // catch: the full KKT system tells whether the constraints hold it.
    return solve_with_fallback(request);
  } catch (const Exception& e) {
    return e.error();
  } catch (const std::bad_alloc&) {
    return Error{ErrorCode::kResourceExhausted, "out of memory while solving"};
  } catch (const std::exception& e) {
    return Error{ErrorCode::kInternal, std::string("internal error: ") + e.what()};
  }
}

Solution Solver::solve_on_cached_factor(const DeformationRequest& request) const {
  {
    const auto start = Clock::now();
    const ShellModel& model = *model_;
    Problem p = build_problem(model, request);
    check_determined(model, p);

    // A cached factor whose prescribed DOFs are a subset of ours; the rest become rows.
    FactorCache::Impl& cache = cache_->impl();
    bool hit = true;
    std::shared_ptr<const Factorization> factor = cache.find_subset(model.id(), p.fixed, kMaxExtraRows);
    if (!factor) {
      factor = cache.get(model.id(), p.fixed,
                         [&] { return std::make_shared<const Factorization>(model, p.fixed, choose_pins(model, p.fixed)); },
                         hit);
    }
    Solution solution;
    solution.stats.path = SolvePath::kCachedFactor;
    solution.stats.factor_cache_hit = hit;
    solution.stats.factor_ms = hit ? 0.0 : factor->factor_ms();

    // Rows: the request's rows plus prescribed DOFs the factor does not eliminate.
    std::vector<Row> rows = p.rows;
    {
      std::vector<int32_t> extra;
      std::set_difference(p.fixed.begin(), p.fixed.end(), factor->fixed().begin(), factor->fixed().end(),
                          std::back_inserter(extra));
      for (int32_t dof : extra) {
        Row row;
        row.terms = {{dof, 1.0}};
        row.rhs = p.fixed_value[dof];
        row.scale = 1.0;
        row.source = "vertex constraint on control point " + std::to_string(dof / 3) + " (" + axis_name(dof % 3) + ")";
        rows.push_back(std::move(row));
      }
    }
    // Rows were reduced with the request's prescribed values; the extra ones re-impose them, so
    // terms on DOFs the factor eliminates never appear.
    const Eigen::SparseMatrix<double>& k = model.stiffness();
    const std::vector<int32_t>& pins = factor->pinned();
    const auto na = static_cast<Eigen::Index>(factor->factored().size());
    const auto nq = static_cast<Eigen::Index>(pins.size());
    const auto nr = static_cast<Eigen::Index>(rows.size());
    solution.stats.constraint_rows = static_cast<int32_t>(nr);

    // Right-hand side of the unknown DOFs: loads minus the pull of the factor's prescribed DOFs
    // (only those prescribed to move pull; K is symmetric, so column j is row j).
    Eigen::VectorXd b = p.load;
    Eigen::VectorXd u_fixed = Eigen::VectorXd::Zero(model.num_dofs());
    for (int32_t dof : factor->fixed()) {
      const double value = p.fixed_value[dof];
      if (value == 0.0) continue;
      u_fixed[dof] = value;
      for (Eigen::SparseMatrix<double>::InnerIterator it(k, dof); it; ++it) b[it.row()] -= it.value() * value;
    }

    // Block right-hand side [b_a | K_aQ | C_a^T] and the small matrix M = [[K_QQ, C_Q^T], [C_Q, 0]].
    std::vector<int32_t> pin_index(static_cast<size_t>(model.num_dofs()), -1);
    for (size_t q = 0; q < pins.size(); ++q) pin_index[static_cast<size_t>(pins[q])] = static_cast<int32_t>(q);
    Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(na, 1 + nq + nr);
    Eigen::MatrixXd m = Eigen::MatrixXd::Zero(nq + nr, nq + nr);
    Eigen::VectorXd b_small = Eigen::VectorXd::Zero(nq + nr);
    for (Eigen::Index i = 0; i < na; ++i) rhs(i, 0) = b[factor->factored()[static_cast<size_t>(i)]];
    for (Eigen::Index q = 0; q < nq; ++q) {
      const int32_t pin = pins[static_cast<size_t>(q)];
      b_small[q] = b[pin];
      for (Eigen::SparseMatrix<double>::InnerIterator it(k, pin); it; ++it) {
        const auto row = static_cast<int32_t>(it.row());
        if (const int32_t a = factor->position(row); a >= 0) {
          rhs(a, 1 + q) = it.value();
        } else if (const int32_t q2 = pin_index[static_cast<size_t>(row)]; q2 >= 0) {
          m(q2, q) = it.value();
        }
      }
    }
    for (Eigen::Index r = 0; r < nr; ++r) {
      const Row& row = rows[static_cast<size_t>(r)];
      b_small[nq + r] = row.rhs;
      for (const auto& [dof, coef] : row.terms) {
        if (const int32_t a = factor->position(dof); a >= 0) {
          rhs(a, 1 + nq + r) += coef;
        } else if (const int32_t q = pin_index[static_cast<size_t>(dof)]; q >= 0) {
          m(nq + r, q) += coef;
          m(q, nq + r) += coef;
        } else {
          fail(ErrorCode::kInternal, "solver: a constraint row refers to an eliminated DOF");
        }
      }
    }

    // Schur complement on the cached factor, with K_aa = P^T L L^T P and Y = L^-1 P [b_a | H]:
    // S = M - Y_H^T Y_H, y = S^-1 (b_small - Y_H^T y_b), u_a = P^T L^-T (y_b - Y_H y). One forward
    // sweep of all columns (only the part of the factor they reach) and one backward sweep of one
    // column: about the cost of one solve.
    const Eigen::MatrixXd forward = factor->forward(rhs, &solution.stats.forward_fraction);
    const auto y_h = forward.rightCols(nq + nr);
    Eigen::MatrixXd schur = m;
    schur.noalias() -= y_h.transpose() * y_h;
    // The pins carry exactly the zero-energy motions the factor's fixed set leaves free, so the
    // Schur complement of K onto them vanishes identically (K_QQ - K_Qa K_aa^-1 K_aQ = 0); what the
    // subtraction leaves is cancellation noise of size eps |K|, which would swamp the constraint
    // block after scaling.
    schur.topLeftCorner(nq, nq).setZero();
    const SmallSystem small(schur);
    Eigen::VectorXd y = small.solve(b_small - y_h.transpose() * forward.col(0));
    Eigen::VectorXd u_a = factor->backward(forward.col(0) - y_h * y);

    // Iterative refinement against the full system's residual: brings the constraints and the
    // equilibrium to round-off even when the small system is large and redundant.
    Eigen::VectorXd u = u_fixed;
    auto scatter = [&] {
      for (Eigen::Index i = 0; i < na; ++i) u[factor->factored()[static_cast<size_t>(i)]] = u_a[i];
      for (Eigen::Index q = 0; q < nq; ++q) u[pins[static_cast<size_t>(q)]] = y[q];
    };
    scatter();
    for (int step = 0; step < 3 && nr + nq > 0; ++step) {
      // Residual of C u = d (cheap: the rows only).
      Eigen::VectorXd res_small(nq + nr);
      double worst = 0.0;
      for (Eigen::Index r = 0; r < nr; ++r) {
        const Row& row = rows[static_cast<size_t>(r)];
        double lhs = 0.0;
        for (const auto& [dof, coef] : row.terms) lhs += coef * u[dof];
        res_small[nq + r] = row.rhs - lhs;
        worst = std::max(worst, std::abs(row.rhs - lhs) / row.scale);
      }
      const double u_scale = u.cwiseAbs().maxCoeff();
      // Without pins the factor's solve is backward stable: equilibrium holds to round-off and
      // only the constraints need checking. With pins, check equilibrium at them too.
      if (nq == 0 && worst <= 1e-13 * u_scale) break;
      // Residual of K u + C^T lambda = b on the unknown DOFs.
      const Eigen::VectorXd ku = k * u;
      Eigen::VectorXd force = p.load - ku;
      for (Eigen::Index r = 0; r < nr; ++r) {
        for (const auto& [dof, coef] : rows[static_cast<size_t>(r)].terms) force[dof] -= coef * y[nq + r];
      }
      Eigen::VectorXd res_a(na);
      for (Eigen::Index i = 0; i < na; ++i) res_a[i] = force[factor->factored()[static_cast<size_t>(i)]];
      for (Eigen::Index q = 0; q < nq; ++q) res_small[q] = force[pins[static_cast<size_t>(q)]];
      // Converged when the constraints hold to ~1e-13 of the displacement scale and equilibrium
      // to ~1e-12 of the forces involved; each further step costs one more pair of sweeps.
      const double f_scale = std::max(p.load.cwiseAbs().maxCoeff(), ku.cwiseAbs().maxCoeff());
      const double equilibrium = std::max(res_a.size() ? res_a.cwiseAbs().maxCoeff() : 0.0,
                                          nq ? res_small.head(nq).cwiseAbs().maxCoeff() : 0.0);
      if (worst <= 1e-13 * u_scale && equilibrium <= 1e-12 * f_scale) break;
      const Eigen::VectorXd z_r = factor->forward(res_a);
      const Eigen::VectorXd dy = small.solve(res_small - y_h.transpose() * z_r);
      u_a += factor->backward(z_r - y_h * dy);
      y += dy;
      scatter();
      ++solution.stats.refinement_steps;
    }
    for (int32_t dof : p.fixed) u[dof] = p.fixed_value[dof];

    check_solution(p, u, model.mesh().bounding_diagonal());
    solution.displacement = std::move(u);
    solution.stats.solve_ms = ms_since(start);
    return solution;
  }
}

Result<Solution> Solver::solve_with_fallback(const DeformationRequest& request) const {
  return capture([&]() -> Solution {
    const auto start = Clock::now();
    const ShellModel& model = *model_;
    Problem p = build_problem(model, request);
    check_determined(model, p);

    // Unknowns: the DOFs that are not prescribed.
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

    // Independent rows only (redundant ones are checked afterwards), scaled to K's magnitude.
    std::vector<size_t> independent;
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
    for (Eigen::Index c = 0; c < nc; ++c) {
      const Row& row = p.rows[independent[static_cast<size_t>(c)]];
      const double w = k_scale / row.scale;
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
    Eigen::VectorXd u = u_fixed;
    for (Eigen::Index i = 0; i < nf; ++i) u[free_dofs[static_cast<size_t>(i)]] = x[i];
    check_solution(p, u, model.mesh().bounding_diagonal());
    Solution solution;
    solution.displacement = std::move(u);
    solution.stats.path = SolvePath::kFallback;
    solution.stats.constraint_rows = static_cast<int32_t>(nc);
    solution.stats.solve_ms = ms_since(start);
    return solution;
  });
}

}  // namespace softshell::engine
