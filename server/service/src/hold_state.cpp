#include "hold_state.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <sstream>
#include <unordered_map>

#include <Eigen/Dense>

#include "service_impl.h"  // request_bytes: one size estimate for stored requests
#include "softshell/content_id.h"
#include "softshell/wire.h"

namespace softshell::service::internal {

namespace {

template <class T>
void append(std::vector<T>& to, const std::vector<T>& from) {
  to.insert(to.end(), from.begin(), from.end());
}

std::string quoted(std::string_view id) { return "'" + std::string(id) + "'"; }

std::string number(double x) {
  std::ostringstream s;
  s.precision(4);
  s << x;
  return s.str();
}

// ---------------------------------------------------------------------------------------------
// Constraint consistency: does C u = d have a solution? Vertex, Lagrange and limit constraints
// act on one axis each (their equations for x, y and z never share an unknown), so each axis
// is a separate small dense system over the control points its rows touch.

struct AxisRow {
  size_t hold = 0;                                  // index into the hold list
  std::vector<std::pair<int32_t, double>> terms;    // (control point, coefficient)
  double rhs = 0.0;
  std::string what;                                 // "vertex constraint 2 (x)"
};

// Systems larger than this are not analysed (the refusal then keeps the solver's message).
constexpr size_t kMaxRows = 3000;
constexpr size_t kMaxEntries = size_t{40} << 20;

class ConstraintRows {
 public:
  ConstraintRows(const HoldMap& holds, const LimitEvaluator& evaluator) {
    const char* axes = "xyz";
    for (const auto& [id, version] : holds) {
      const size_t h = ids_.size();
      ids_.push_back(id);
      const DeformationRequest& r = version->request;
      for (size_t k = 0; k < r.vertex_constraints.size(); ++k) {
        const VertexConstraint& c = r.vertex_constraints[k];
        for (int a = 0; a < 3; ++a) {
          if (!(c.mask & (1u << a))) continue;
          rows_[a].push_back({h, {{c.index, 1.0}}, c.displacement[a],
                              "vertex constraint " + std::to_string(k) + " (" + axes[a] + ")"});
        }
      }
      for (size_t k = 0; k < r.lagrange_constraints.size(); ++k) {
        const LagrangeConstraint& c = r.lagrange_constraints[k];
        for (int a = 0; a < 3; ++a) {
          AxisRow row{h, {}, c.values[a], "Lagrange constraint " + std::to_string(k) + " (" + axes[a] + ")"};
          for (size_t j = 0; j < c.indices.size(); ++j) row.terms.push_back({c.indices[j], c.coefficients[j][a]});
          rows_[a].push_back(std::move(row));
        }
      }
      LimitStencil st;
      for (size_t k = 0; k < r.limit_constraints.size(); ++k) {
        const LimitConstraint& c = r.limit_constraints[k];
        evaluator.stencil(c.point, st);
        auto add = [&](const std::vector<double>& weights, const Vec3& target, const char* kind) {
          for (int a = 0; a < 3; ++a) {
            AxisRow row{h, {}, target[a], "limit constraint " + std::to_string(k) + " (" + kind + axes[a] + ")"};
            for (size_t j = 0; j < st.size(); ++j) row.terms.push_back({st.indices[j], weights[j]});
            rows_[a].push_back(std::move(row));
          }
        };
        add(st.position, c.displacement, "");
        if (c.du_displacement) add(st.du, *c.du_displacement, "du ");
        if (c.dv_displacement) add(st.dv, *c.dv_displacement, "dv ");
      }
    }
  }

  size_t index_of(std::string_view id) const {
    return static_cast<size_t>(std::find(ids_.begin(), ids_.end(), id) - ids_.begin());
  }
  const std::string& id(size_t h) const { return ids_[h]; }
  size_t size() const { return ids_.size(); }

  // True if consistent (or too large to analyse); otherwise `detail` names the worst equation.
  bool consistent(const std::vector<char>& include, double length, std::string* detail) const {
    for (int a = 0; a < 3; ++a) {
      std::vector<const AxisRow*> rows;
      for (const AxisRow& row : rows_[a]) {
        if (!include[row.hold]) continue;
        const bool zero = std::all_of(row.terms.begin(), row.terms.end(), [](const auto& t) { return t.second == 0.0; });
        if (!zero) {
          rows.push_back(&row);
        } else if (row.rhs != 0.0) {  // 0 = rhs (dropped when rhs = 0, as the solver does)
          if (detail) {
            *detail = row.what + " of hold " + quoted(ids_[row.hold]) + " has only zero coefficients but asks for " +
                      number(row.rhs);
          }
          return false;
        }
      }
      if (rows.empty()) continue;
      std::unordered_map<int32_t, Eigen::Index> column;
      for (const AxisRow* row : rows) {
        for (const auto& [cp, coef] : row->terms) {
          if (coef != 0.0) column.emplace(cp, static_cast<Eigen::Index>(column.size()));
        }
      }
      if (rows.size() > kMaxRows || rows.size() * column.size() > kMaxEntries) continue;
      const auto nr = static_cast<Eigen::Index>(rows.size());
      Eigen::MatrixXd c = Eigen::MatrixXd::Zero(nr, static_cast<Eigen::Index>(column.size()));
      Eigen::VectorXd d(nr);
      for (Eigen::Index i = 0; i < nr; ++i) {
        const AxisRow& row = *rows[static_cast<size_t>(i)];
        for (const auto& [cp, coef] : row.terms) {
          if (coef != 0.0) c(i, column.at(cp)) += coef;
        }
        const double scale = c.row(i).cwiseAbs().maxCoeff();
        c.row(i) /= scale > 0.0 ? scale : 1.0;  // (terms that cancel leave 0 = rhs, judged below)
        d[i] = scale > 0.0 ? row.rhs / scale : row.rhs;
      }
      Eigen::VectorXd x = Eigen::VectorXd::Zero(c.cols());
      if (c.cols() > 0) {
        Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod;
        cod.setThreshold(1e-10);
        cod.compute(c);
        x = cod.solve(d);
      }
      const Eigen::VectorXd residual = c * x - d;
      const double scale = std::max({d.cwiseAbs().maxCoeff(), x.size() ? x.cwiseAbs().maxCoeff() : 0.0, 1e-12 * length});
      Eigen::Index worst = 0;
      const double miss = residual.cwiseAbs().maxCoeff(&worst);
      if (miss > 1e-8 * scale) {
        if (detail) {
          const AxisRow& row = *rows[static_cast<size_t>(worst)];
          *detail = "their constraints cannot all be met at once (" + row.what + " of hold " + quoted(ids_[row.hold]) +
                    " misses by " + number(std::abs(residual[worst])) + " in the best compromise)";
        }
        return false;
      }
    }
    return true;
  }

 private:
  std::vector<std::string> ids_;
  std::array<std::vector<AxisRow>, 3> rows_;
};

std::string keeps(const std::string& hold_id, uint64_t previous) {
  return previous ? "; hold " + quoted(hold_id) + " keeps its previous contents (version " + std::to_string(previous) + ")"
                  : "; hold " + quoted(hold_id) + " was not created";
}

}  // namespace

Result<std::shared_ptr<HoldVersion>> make_hold_version(DeformationRequest request, MemoryBudget& budget) {
  auto v = std::make_unique<HoldVersion>();
  v->canonical = wire::encode_request_json(request);
  const auto digest = sha256(v->canonical);
  std::memcpy(v->key.data(), digest.data(), v->key.size());
  // The contents twice (decoded and canonical), and the hold's lease and bookkeeping.
  v->bytes = sizeof(HoldVersion) + v->canonical.size() + request_bytes(request) + 512;
  v->request = std::move(request);
  if (!budget.try_reserve(v->bytes)) {
    return Error{ErrorCode::kResourceExhausted,
                 "the server's memory budget (" + std::to_string(budget.budget() >> 20) + " MiB, " +
                     std::to_string(budget.used() >> 20) + " MiB in use) cannot hold this hold's contents (" +
                     std::to_string(v->bytes) + " bytes); release holds or restart the server with a larger --store-mb"};
  }
  MemoryBudget* b = &budget;
  return std::shared_ptr<HoldVersion>(v.release(), [b](HoldVersion* p) {
    b->release(p->bytes);
    delete p;
  });
}

HoldVersions versions_of(const HoldMap& holds) {
  HoldVersions out;
  out.reserve(holds.size());
  for (const auto& [id, v] : holds) out.emplace_back(id, v->version);
  return out;
}

DeformationModel model_of(const HoldMap& holds) {
  const bool nonlinear = std::any_of(holds.begin(), holds.end(), [](const auto& h) {
    return h.second->request.model == DeformationModel::kNonlinear;
  });
  return nonlinear ? DeformationModel::kNonlinear : DeformationModel::kLinear;
}

AssembledHoldState assemble(const HoldMap& holds) {
  AssembledHoldState s;
  DeformationRequest& m = s.merged;
  m.model = model_of(holds);
  for (const auto& [id, v] : holds) {
    const DeformationRequest& r = v->request;
    HoldBlock b;
    b.hold_id = id;
    b.version = v->version;
    b.key = &v->key;
    b.request = &r;
    b.vertex_begin = m.vertex_constraints.size();
    b.lagrange_begin = m.lagrange_constraints.size();
    b.limit_begin = m.limit_constraints.size();
    append(m.vertex_constraints, r.vertex_constraints);
    append(m.lagrange_constraints, r.lagrange_constraints);
    append(m.limit_constraints, r.limit_constraints);
    append(m.forces, r.forces);
    append(m.surface_forces, r.surface_forces);
    m.surface_load += r.surface_load;
    m.pressure += r.pressure;
    b.vertex_end = m.vertex_constraints.size();
    b.lagrange_end = m.lagrange_constraints.size();
    b.limit_end = m.limit_constraints.size();
    s.blocks.push_back(b);
  }
  return s;
}

Result<HoldSolution> solve_hold_state(const HoldSolvers& solvers, const AssembledHoldState& state) {
  HoldSolution out;
  if (state.blocks.empty()) {
    out.displacement = Eigen::VectorXd::Zero(solvers.linear.model().num_dofs());
    return out;
  }
  if (state.merged.model == DeformationModel::kNonlinear) {
    const Eigen::VectorXd* previous = solvers.previous;
    if (previous && previous->size() != solvers.nonlinear.model().num_dofs()) previous = nullptr;
    const auto start = std::chrono::steady_clock::now();
    auto answer = previous ? solvers.nonlinear.solve(state.merged, *previous) : solvers.nonlinear.solve(state.merged);
    // From rest, once, unless the first try used up the time a solve may take.
    const double limit = solvers.nonlinear.options().time_limit_seconds;
    const bool out_of_time =
        limit > 0.0 && std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >= limit;
    if (!answer && previous && answer.error().code == ErrorCode::kUnprocessable && !out_of_time) {
      answer = solvers.nonlinear.solve(state.merged);
    }
    if (!answer) return answer.error();
    out.displacement = std::move(answer->displacement);
    out.nonlinear = answer->stats;
    return out;
  }
  auto answer = solvers.linear.solve(state.merged);
  if (!answer) return answer.error();
  out.displacement = std::move(answer->displacement);
  out.stats = answer->stats;
  return out;
}

bool constraints_consistent(const HoldMap& holds, const std::vector<std::string>& subset,
                            const LimitEvaluator& evaluator, double length, std::string* detail) {
  const ConstraintRows rows(holds, evaluator);
  std::vector<char> include(rows.size(), 0);
  for (const auto& id : subset) {
    if (const size_t h = rows.index_of(id); h < rows.size()) include[h] = 1;
  }
  return rows.consistent(include, length, detail);
}

Error explain_refusal(const HoldMap& trial, const std::string& hold_id, uint64_t previous, const Error& solve_error,
                      const LimitEvaluator& evaluator, double length) {
  if (solve_error.code != ErrorCode::kUnprocessable) return solve_error;
  const uint64_t version = trial.at(hold_id)->version;
  const std::string self = "hold " + quoted(hold_id) + " (version " + std::to_string(version) + ")";
  try {
    const ConstraintRows rows(trial, evaluator);
    const size_t me = rows.index_of(hold_id);
    std::vector<char> include(rows.size(), 0);
    include[me] = 1;
    std::string detail;
    if (!rows.consistent(include, length, &detail)) {
      return Error{ErrorCode::kUnprocessable, self + " contradicts itself: " + detail + keeps(hold_id, previous)};
    }
    std::fill(include.begin(), include.end(), 1);
    if (rows.consistent(include, length, &detail)) {
      return Error{ErrorCode::kUnprocessable,
                   "with " + self + " the hold state cannot be solved: " + solve_error.message + keeps(hold_id, previous)};
    }
    // A smallest set of other holds it contradicts: those it contradicts one by one, else the
    // set left after dropping every hold without which the contradiction remains.
    std::vector<size_t> named;
    for (size_t h = 0; h < rows.size(); ++h) {
      if (h == me) continue;
      std::vector<char> pair(rows.size(), 0);
      pair[me] = pair[h] = 1;
      if (!rows.consistent(pair, length, nullptr)) named.push_back(h);
    }
    if (named.empty() && rows.size() <= 65) {
      std::vector<char> set = include;
      for (size_t h = 0; h < rows.size(); ++h) {
        if (h == me) continue;
        set[h] = 0;
        if (rows.consistent(set, length, nullptr)) set[h] = 1;  // needed for the contradiction
      }
      for (size_t h = 0; h < rows.size(); ++h) {
        if (h != me && set[h]) named.push_back(h);
      }
    }
    std::string others;
    for (size_t i = 0; i < named.size(); ++i) {
      const std::string& id = rows.id(named[i]);
      others += (i ? ", " : "") + quoted(id) + " (version " + std::to_string(trial.at(id)->version) + ")";
    }
    if (others.empty()) others = "the other live holds";
    std::string pair_detail;
    if (named.size() == 1) {
      std::vector<char> pair(rows.size(), 0);
      pair[me] = pair[named[0]] = 1;
      rows.consistent(pair, length, &pair_detail);
    }
    return Error{ErrorCode::kConflict, self + " contradicts the live hold" + (named.size() == 1 ? " " : "s ") + others +
                                           ": " + (pair_detail.empty() ? detail : pair_detail) + keeps(hold_id, previous)};
  } catch (const Exception& e) {
    return Error{ErrorCode::kUnprocessable, self + ": " + solve_error.message + " (" + e.what() + ")" + keeps(hold_id, previous)};
  }
}

}  // namespace softshell::service::internal
