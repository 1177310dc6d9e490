#include "problem.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/Dense>

#include "request_check.h"

namespace softshell::engine::internal {

std::string format_number(double x) {
  std::ostringstream s;
  s.precision(3);
  s << x;
  return s.str();
}

std::string axis_name(int a) { return std::string(1, "xyz"[a]); }

namespace {

std::string format_vec(Vec3 v) {
  // Round-off noise shown as 0 (and never as -0).
  const double top = v.cwiseAbs().maxCoeff();
  for (int i = 0; i < 3; ++i) v[i] = std::abs(v[i]) <= 1e-9 * top ? 0.0 : v[i];
  std::ostringstream s;
  s.precision(4);
  s << "(" << v.x() << ", " << v.y() << ", " << v.z() << ")";
  return s.str();
}

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

}  // namespace

Problem build_problem(const ShellModel& model, const DeformationRequest& request) {
  check_constraints(model, request);
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
      row.lagrange = static_cast<int32_t>(i);
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
        row.limit = static_cast<int32_t>(i);
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

namespace {

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

}  // namespace

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
Pins choose_pins(const ShellModel& model, const std::vector<int32_t>& fixed) {
  Pins pins;
  const Eigen::MatrixXd null = free_rigid_combinations(model, fixed);
  if (null.cols() == 0) return pins;
  pins.motions = model.zero_energy_modes() * null;  // 3n x r
  for (int32_t dof : fixed) pins.motions.row(dof).setZero();
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(pins.motions.transpose());
  for (Eigen::Index k = 0; k < null.cols(); ++k) pins.dofs.push_back(static_cast<int32_t>(qr.colsPermutation().indices()[k]));
  std::sort(pins.dofs.begin(), pins.dofs.end());
  return pins;
}

RowCheck check_row(const Row& row, const Eigen::VectorXd& u, double displacement_scale, double size) {
  double lhs = 0.0, terms = std::abs(row.rhs);
  for (const auto& [dof, coef] : row.terms) {
    lhs += coef * u[dof];
    terms += std::abs(coef * u[dof]);
  }
  return {std::abs(lhs - row.rhs), row.scale * (kConstraint * displacement_scale + kGeometry * size) + kRoundOff * terms};
}

}  // namespace softshell::engine::internal
