#include "nonlinear_shell.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <Eigen/Dense>

#include "kirchhoff_love.h"
#include "nonlinear_element.h"
#include "quadrature.h"

namespace softshell::engine::internal {

using namespace nonlinear_kernel;
using V3 = Eigen::Vector3d;

namespace {

// A thread's scratch arrays for the element kernels, kept between elements and passes: fresh
// zero-filled arrays per element were a memset of the size of the whole state per pass.
struct Scratch {
  std::vector<double> values, coef;  // 18 P each (the kernels write every entry they read)
  std::vector<PieceView> pieces;    // the element's pieces
};

template <class Rule, class Element>
Scratch& thread_scratch(const Rule& rule, const Element& e) {
  thread_local Scratch scratch;
  const auto size = static_cast<size_t>(18 * e.points);
  if (scratch.values.size() < size) {
    scratch.values.resize(size);
    scratch.coef.resize(size);
  }
  scratch.pieces.clear();
  for (const auto& pc : e.pieces) {
    const bool bernstein = pc.size > 0.0;
    const auto g = static_cast<size_t>(pc.gauss);
    scratch.pieces.push_back({pc.w.data(), pc.w.rows(), pc.first, pc.points, pc.size,
                              bernstein ? rule.bernstein[g].data() : nullptr,
                              bernstein ? rule.bernstein_t[g].data() : nullptr});
  }
  return scratch;
}

}  // namespace

int NonlinearShell::workers(int requested) const {
  const int most = executor_->concurrency();
  return requested > 0 ? std::min(requested, most) : most;
}

int NonlinearShell::pass_threads(const Rule& rule) const {
  return rule.points < 2048 ? 1 : workers(threads_);  // (fewer points: a second thread costs more than it saves)
}

template <class Fn>
void NonlinearShell::for_each_element(const Rule& rule, Fn&& fn) const {
  // Chunks of about the same number of points, so both threads finish together.
  constexpr size_t kPointsPerChunk = 1024;
  const int threads = pass_threads(rule);
  if (threads == 1) {
    for (size_t e = 0; e < rule.elements.size(); ++e) fn(e);
    return;
  }
  std::vector<size_t> starts{0};
  size_t points = 0;
  for (size_t e = 0; e < rule.elements.size(); ++e) {
    points += static_cast<size_t>(rule.elements[e].points);
    if (points >= kPointsPerChunk) {
      starts.push_back(e + 1);
      points = 0;
    }
  }
  if (starts.back() != rule.elements.size()) starts.push_back(rule.elements.size());
  executor_->parallel_for(0, static_cast<int64_t>(starts.size() - 1), [&](int64_t c) {
    for (size_t e = starts[static_cast<size_t>(c)]; e < starts[static_cast<size_t>(c) + 1]; ++e) fn(e);
  }, threads);
}

template <class Fn>
void NonlinearShell::for_each_control_point_range(const Rule& rule, Fn&& fn) const {
  constexpr int64_t kPointsPerChunk = 64;
  const auto n = static_cast<int64_t>(rule.touch_start.size()) - 1;
  const int threads = pass_threads(rule);
  if (threads == 1) {
    fn(int32_t{0}, static_cast<int32_t>(n));
    return;
  }
  executor_->parallel_for(0, (n + kPointsPerChunk - 1) / kPointsPerChunk, [&](int64_t c) {
    fn(static_cast<int32_t>(c * kPointsPerChunk), static_cast<int32_t>(std::min(n, (c + 1) * kPointsPerChunk)));
  }, threads);
}

template <class Fn>
void NonlinearShell::for_each_control_point(const Rule& rule, Fn&& fn) const {
  for_each_control_point_range(rule, [&](int32_t begin, int32_t end) {
    for (int32_t p = begin; p < end; ++p) fn(p);
  });
}

std::array<double, 3> NonlinearShell::gathered(const Rule& rule, const double* rows, Eigen::Index width, int32_t p,
                                                Eigen::Index k) {
  std::array<double, 3> sum{0.0, 0.0, 0.0};  // (three chains of additions at once)
  const auto pi = static_cast<size_t>(p);
  for (size_t t = rule.touch_start[pi]; t < rule.touch_start[pi + 1]; ++t) {
    const auto e = static_cast<size_t>(rule.touches[t][0]);
    const auto first = rule.element_rows[e];
    const auto m = static_cast<Eigen::Index>(rule.element_rows[e + 1] - first);
    const double* row = rows + static_cast<Eigen::Index>(first) * width + k * m + rule.touches[t][1];
    sum[0] += row[0];
    sum[1] += row[m];
    sum[2] += row[2 * m];
  }
  return sum;
}

void NonlinearShell::build_rule(const std::vector<Cell>& cells, const std::vector<int>& gauss, int threads,
                                Rule& rule) const {
  const ShellModel& m = *model_;
  rule.elements.resize(cells.size());
  size_t points = 0;
  for (size_t c = 0; c < cells.size(); ++c) {
    rule.elements[c].first_point = points;
    rule.elements[c].points = static_cast<Eigen::Index>(cells[c].uvs.size());
    points += cells[c].uvs.size();
  }
  rule.points = points;
  rule.reference.assign(kRef * points, 0.0);
  std::array<Eigen::HouseholderQR<Eigen::MatrixXd>, 11> bernstein_qr;
  std::array<std::vector<double>, 11> gp;
  std::vector<int> cell_rules;  // the Gauss rules of cells a piece can be (2 points or more)
  for (int g : gauss) {
    const auto at = static_cast<size_t>(g);
    if (g < 2 || g > 10 || rule.bernstein[at].size() != 0) continue;
    cell_rules.push_back(g);
    rule.bernstein[at] = bernstein_basis(g);
    rule.bernstein_t[at] = rule.bernstein[at].transpose();
    bernstein_qr[at].compute(rule.bernstein[at]);
    std::vector<double> gw;
    gauss_legendre_01(g, gp[at], gw);
  }
  const Eigen::SparseMatrix<double>& k = m.stiffness();
  const Material& mat = m.material();
  const double t = mat.thickness;
  executor_->parallel_for(0, static_cast<int64_t>(cells.size()), [&](int64_t ci) {
    const Cell& cell = cells[static_cast<size_t>(ci)];
    Element& e = rule.elements[static_cast<size_t>(ci)];
    const auto p = e.points;
    Eigen::MatrixXd bfr;  // 6P x m, rows 6q + d
    m.evaluator().face_stencils(cell.face, cell.subface, cell.uvs, e.indices, bfr);
    const auto mm = static_cast<Eigen::Index>(e.indices.size());
    Eigen::MatrixXd basis(kRows * p, mm);
    for (Eigen::Index q = 0; q < p; ++q) {
      for (int d = 0; d < kRows; ++d) basis.row(d * p + q) = bfr.row(kRows * q + d);
    }
    Eigen::MatrixX3d x(mm, 3);
    for (Eigen::Index a = 0; a < mm; ++a) {
      x.row(a) = m.mesh().positions()[static_cast<size_t>(e.indices[static_cast<size_t>(a)])].transpose();
    }
    const Eigen::MatrixX3d deriv = basis * x;
    SurfaceFrame frame;
    for (Eigen::Index q = 0; q < p; ++q) {
      // The same frame and material matrix the linear model was integrated with.
      if (!compute_frame(bfr.middleRows(kRows * q, kRows), x, mat.youngs_modulus, mat.poisson_ratio, frame)) {
        fail(ErrorCode::kUnprocessable, "nonlinear shell: the limit surface of face " + std::to_string(cell.face) +
                                            " is degenerate at a quadrature point");
      }
      double ref[kRef];
      for (int d = 1; d < kRows; ++d) store3(ref + 3 * (d - 1), deriv.row(d * p + q).transpose());
      const V3 t3 = load3(ref).cross(load3(ref + 3));
      store3(ref + 15, t3 / t3.norm());
      ref[18] = t3.norm();
      const double weight = cell.weights[static_cast<size_t>(q)];
      const double da = weight * frame.j;
      const Eigen::Matrix3d& c = frame.material;
      const double packed[6] = {c(0, 0), c(1, 1), c(2, 2), c(0, 1), c(0, 2), c(1, 2)};
      for (int i = 0; i < 6; ++i) ref[19 + i] = da * t * packed[i];
      ref[25] = weight;
      // Stored by quantity (nonlinear_element.h).
      double* stored = rule.reference.data() + kRef * e.first_point;
      for (int i = 0; i < kRef; ++i) stored[i * p + q] = ref[i];
    }
    // Pieces: each run of g^2 points that is a square cell of a g-point Gauss rule (points at
    // u0 + s x_i, v0 + s x_j) and on which the basis is a bicubic polynomial to round-off keeps 16
    // Bernstein coefficients per control point instead of its weights (a ninth to a sixth of the
    // bytes a pass streams). The cells of deep rings toward an extraordinary vertex have their own
    // rule; the innermost cell there, which holds infinitely many rings, is not polynomial.
    auto take_weights = [&](Eigen::Index first, Eigen::Index count) {
      Piece piece;
      piece.first = first;
      piece.points = count;
      piece.w.resize(kRows * count, mm);
      for (int d = 0; d < kRows; ++d) piece.w.middleRows(d * count, count) = basis.middleRows(d * p + first, count);
      return piece;
    };
    // The edge length of the square cell of g-point Gauss points starting at `first` (0: not one).
    auto square_cell = [&](Eigen::Index first, int g) {
      const std::vector<double>& nodes = gp[static_cast<size_t>(g)];
      const auto& start = cell.uvs[static_cast<size_t>(first)];
      const double size = (cell.uvs[static_cast<size_t>(first) + 1][0] - start[0]) / (nodes[1] - nodes[0]);
      if (!(size > 0.0)) return 0.0;
      const double u0 = start[0] - size * nodes[0], v0 = start[1] - size * nodes[0];
      for (Eigen::Index q = 0; q < static_cast<Eigen::Index>(g) * g; ++q) {
        const auto& uv = cell.uvs[static_cast<size_t>(first + q)];
        if (std::abs(uv[0] - (u0 + size * nodes[static_cast<size_t>(q % g)])) > 1e-12 ||
            std::abs(uv[1] - (v0 + size * nodes[static_cast<size_t>(q / g)])) > 1e-12) {
          return 0.0;
        }
      }
      return size;
    };
    // The piece's Bernstein coefficients if the basis is bicubic on it to round-off.
    auto fit = [&](Piece& piece, int g, double size) {
      const auto n = piece.points;
      // Fit on the unit cell: derivatives of order k carry size^k.
      Eigen::MatrixXd scaled = piece.w;
      for (int d = 0; d < kRows; ++d) scaled.middleRows(d * n, n) *= std::pow(size, kOrder[d]);
      const Eigen::MatrixXd coef = bernstein_qr[static_cast<size_t>(g)].solve(scaled);
      const Eigen::MatrixXd back = rule.bernstein[static_cast<size_t>(g)] * coef;
      const double overall = scaled.cwiseAbs().maxCoeff();
      for (int d = 0; d < kRows; ++d) {
        const auto block = scaled.middleRows(d * n, n);
        const double top = std::max(block.cwiseAbs().maxCoeff(), 1e-6 * overall);
        if ((back.middleRows(d * n, n) - block).cwiseAbs().maxCoeff() > 1e-11 * top) return;
      }
      piece.w = coef;
      piece.size = size;
      piece.gauss = g;
    };
    Eigen::Index first = 0, loose = 0;  // points [loose, first) go into one piece with weights
    while (first < p) {
      bool cell_found = false;
      for (int g : cell_rules) {
        const Eigen::Index n = static_cast<Eigen::Index>(g) * g;
        if (first + n > p) continue;
        const double size = square_cell(first, g);
        if (size == 0.0) continue;
        if (first > loose) e.pieces.push_back(take_weights(loose, first - loose));
        Piece piece = take_weights(first, n);
        fit(piece, g, size);
        e.pieces.push_back(std::move(piece));
        first += n;
        loose = first;
        cell_found = true;
        break;
      }
      if (!cell_found) ++first;
    }
    if (p > loose) e.pieces.push_back(take_weights(loose, p - loose));
    // Where each (a, b) block of the element lands in K's value array.
    e.offsets.resize(static_cast<size_t>(mm * mm));
    for (Eigen::Index bl = 0; bl < mm; ++bl) {
      const int col = 3 * e.indices[static_cast<size_t>(bl)];
      const int* begin = k.innerIndexPtr() + k.outerIndexPtr()[col];
      const int* end = k.innerIndexPtr() + k.outerIndexPtr()[col + 1];
      for (Eigen::Index al = 0; al < mm; ++al) {
        const int row = 3 * e.indices[static_cast<size_t>(al)];
        const int* it = std::lower_bound(begin, end, row);
        if (it == end || *it != row || end - it < 3 || it[2] != row + 2) {
          fail(ErrorCode::kInternal, "nonlinear shell: the stiffness pattern lacks an element's block");
        }
        e.offsets[static_cast<size_t>(al + mm * bl)] = static_cast<int32_t>(it - begin);
      }
    }
  }, workers(threads));
  const size_t ne = rule.elements.size();
  rule.element_rows.assign(ne + 1, 0);
  rule.touch_start.assign(static_cast<size_t>(m.num_dofs() / 3) + 1, 0);
  for (size_t e = 0; e < ne; ++e) {
    rule.element_rows[e + 1] = rule.element_rows[e] + rule.elements[e].indices.size();
    for (int32_t p : rule.elements[e].indices) ++rule.touch_start[static_cast<size_t>(p) + 1];
  }
  for (size_t p = 1; p < rule.touch_start.size(); ++p) rule.touch_start[p] += rule.touch_start[p - 1];
  rule.touches.resize(rule.touch_start.back());
  std::vector<size_t> next(rule.touch_start.begin(), rule.touch_start.end() - 1);
  for (size_t e = 0; e < ne; ++e) {
    const std::vector<int32_t>& indices = rule.elements[e].indices;
    for (size_t a = 0; a < indices.size(); ++a) {
      rule.touches[next[static_cast<size_t>(indices[a])]++] = {static_cast<int32_t>(e), static_cast<int32_t>(a)};
    }
  }
}

std::shared_ptr<const NonlinearShell> NonlinearShell::build(std::shared_ptr<const ShellModel> model, int threads,
                                                            int jacobian_gauss_points,
                                                            std::shared_ptr<Executor> executor,
                                                            int early_rule_levels) {
  if (!model) fail(ErrorCode::kInvalidArgument, "NonlinearShell needs a model");
  if (jacobian_gauss_points < 0 || jacobian_gauss_points > 10) {
    fail(ErrorCode::kInvalidArgument, "NonlinearShell: jacobian_gauss_points must be 0..10");
  }
  if (early_rule_levels < -1 || early_rule_levels > 8) {
    fail(ErrorCode::kInvalidArgument, "NonlinearShell: early_rule_levels must be -1 (none) or 0..8");
  }
  std::shared_ptr<NonlinearShell> shell(new NonlinearShell());
  shell->model_ = model;
  shell->threads_ = threads;
  shell->executor_ = executor ? std::move(executor) : default_executor();
  const ShellModel& m = *model;
  // The model's rule: the runs of quadrature points on one (face, sub-face), in the order K was
  // built.
  std::vector<Cell> cells;
  const std::vector<QuadraturePoint>& quad = m.quadrature();
  for (size_t q = 0; q < quad.size(); ++q) {
    if (q == 0 || quad[q].point.face != quad[q - 1].point.face || quad[q].point.subface != quad[q - 1].point.subface) {
      cells.push_back(Cell{quad[q].point.face, quad[q].point.subface, {}, {}});
    }
    cells.back().uvs.push_back({quad[q].point.u, quad[q].point.v});
    cells.back().weights.push_back(quad[q].weight);
  }
  const QuadratureOptions& quadrature = m.options().quadrature;
  shell->build_rule(cells, {quadrature.gauss_points, quadrature.ev_ring_gauss_points}, threads, shell->fine_);
  if (early_rule_levels >= 0 && early_rule_levels < quadrature.ev_refinement_levels) {
    // The model's rule with fewer levels, built as the model's is (face_rule).
    QuadratureOptions early = quadrature;
    early.ev_refinement_levels = early_rule_levels;
    const IrregularCorners irregular(m.evaluator().mesh());
    std::vector<Cell> early_cells(cells.size());
    shell->executor_->parallel_for(0, static_cast<int64_t>(cells.size()), [&](int64_t c) {
      const Cell& cell = cells[static_cast<size_t>(c)];
      FaceRule rule;
      face_rule(m.evaluator(), early, cell.face, cell.subface, irregular.corners(cell.face, cell.subface), rule);
      early_cells[static_cast<size_t>(c)] = Cell{cell.face, cell.subface, std::move(rule.uvs), std::move(rule.weights)};
    }, shell->workers(threads));
    size_t points = 0;
    for (const Cell& cell : early_cells) points += cell.uvs.size();
    // Fewer points by a third or more, or it is not worth its memory.
    if (3 * points <= 2 * shell->fine_.points) {
      shell->build_rule(early_cells, {quadrature.gauss_points, quadrature.ev_ring_gauss_points}, threads, shell->early_);
    }
  }
  if (jacobian_gauss_points > 0) {
    std::vector<double> gp, gw;
    gauss_legendre_01(jacobian_gauss_points, gp, gw);
    for (Cell& cell : cells) {
      cell.uvs.clear();
      cell.weights.clear();
      for (size_t j = 0; j < gp.size(); ++j) {
        for (size_t i = 0; i < gp.size(); ++i) {
          cell.uvs.push_back({gp[i], gp[j]});
          cell.weights.push_back(gw[i] * gw[j]);
        }
      }
    }
    shell->build_rule(cells, {jacobian_gauss_points}, threads, shell->coarse_);
    ShellState rest;
    if (!shell->evaluate_rule(shell->coarse_, Eigen::VectorXd::Zero(m.num_dofs()), rest, false)) {
      fail(ErrorCode::kUnprocessable, "nonlinear shell: the limit surface is degenerate at a coarse quadrature point");
    }
    Eigen::SparseMatrix<double> coarse_rest;
    shell->assemble_rule(shell->coarse_, rest, 0.0, coarse_rest);
    // K - K_coarse(0) value by value: both are on K's pattern (assemble_rule).
    shell->coarse_error_ = m.stiffness();
    double* error = shell->coarse_error_.valuePtr();
    for (Eigen::Index i = 0; i < coarse_rest.nonZeros(); ++i) error[i] -= coarse_rest.valuePtr()[i];
    // Symmetric bit for bit (it is, both matrices are built so; this makes sure): its rows are its
    // columns, so approximate_tangent_product takes it by rows on both threads with the bits of a
    // one-thread product by columns.
    const Eigen::SparseMatrix<double> transposed = shell->coarse_error_.transpose();
    const Eigen::SparseMatrix<double>& e = shell->coarse_error_;
    if (!std::equal(transposed.outerIndexPtr(), transposed.outerIndexPtr() + e.cols() + 1, e.outerIndexPtr()) ||
        !std::equal(transposed.innerIndexPtr(), transposed.innerIndexPtr() + e.nonZeros(), e.innerIndexPtr())) {
      fail(ErrorCode::kInternal, "nonlinear shell: the stiffness pattern is not symmetric");
    }
    // And made of 3 x 3 blocks: the product reads columns 3c + 1 and 3c + 2 at column 3c's rows.
    const int* outer = e.outerIndexPtr();
    const int* inner = e.innerIndexPtr();
    for (Eigen::Index c = 0; c + 2 < e.cols(); c += 3) {
      const int length = outer[c + 1] - outer[c];
      for (int i = 1; i <= 2; ++i) {
        if (outer[c + i + 1] - outer[c + i] != length ||
            !std::equal(inner + outer[c], inner + outer[c + 1], inner + outer[c + i])) {
          fail(ErrorCode::kInternal, "nonlinear shell: the stiffness pattern is not made of 3 x 3 blocks");
        }
      }
    }
    for (Eigen::Index i = 0; i < transposed.nonZeros(); ++i) error[i] = 0.5 * (error[i] + transposed.valuePtr()[i]);
  }
  shell->bytes_ = shell->count_bytes();
  return shell;
}

Eigen::MatrixXd NonlinearShell::element_basis(const Rule& rule, const Element& e) {
  const auto p = e.points;
  Eigen::MatrixXd basis(kRows * p, static_cast<Eigen::Index>(e.indices.size()));
  for (const Piece& piece : e.pieces) {
    const Eigen::Index n = piece.points;
    if (piece.size > 0.0) {
      const Eigen::MatrixXd w = rule.bernstein[static_cast<size_t>(piece.gauss)] * piece.w;
      for (int d = 0; d < kRows; ++d) {
        basis.middleRows(d * p + piece.first, n) = w.middleRows(d * n, n) / std::pow(piece.size, kOrder[d]);
      }
    } else {
      for (int d = 0; d < kRows; ++d) basis.middleRows(d * p + piece.first, n) = piece.w.middleRows(d * n, n);
    }
  }
  return basis;
}

size_t NonlinearShell::memory_bytes() const {
  std::lock_guard lock(workspace_mutex_);
  size_t bytes = bytes_;
  for (const auto& w : workspaces_) bytes += w->capacity() * sizeof(double);
  return bytes;
}

NonlinearShell::Workspace NonlinearShell::take_workspace(size_t size, bool rows) const {
  auto& pool = rows ? row_workspaces_ : workspaces_;
  std::unique_ptr<std::vector<double>> w;
  {
    std::lock_guard lock(workspace_mutex_);
    if (!pool.empty()) {
      w = std::move(pool.back());
      pool.pop_back();
    }
  }
  if (!w) w = std::make_unique<std::vector<double>>();
  w->resize(size);
  return Workspace(w.release(), [this, &pool](std::vector<double>* done) {
    std::lock_guard lock(workspace_mutex_);
    pool.emplace_back(done);
  });
}

size_t NonlinearShell::count_bytes() const {
  size_t bytes = sizeof(*this);
  bytes += static_cast<size_t>(coarse_error_.nonZeros()) * (sizeof(double) + sizeof(int));
  for (const Rule* rule : {&fine_, &coarse_, &early_}) {
    bytes += rule->reference.size() * sizeof(double);
    bytes += (rule->element_rows.size() + rule->touch_start.size()) * sizeof(size_t) +
             rule->touches.size() * sizeof(rule->touches[0]);
    for (const Element& e : rule->elements) {
      bytes += sizeof(Element) + (e.indices.size() + e.offsets.size()) * sizeof(int32_t);
      for (const Piece& piece : e.pieces) bytes += sizeof(Piece) + static_cast<size_t>(piece.w.size()) * sizeof(double);
    }
  }
  return bytes;
}

bool NonlinearShell::evaluate(const Eigen::VectorXd& u, ShellState& state, bool with_pressure,
                              bool with_points) const {
  state.early = false;
  return evaluate_rule(fine_, u, state, with_pressure, with_points);
}

bool NonlinearShell::evaluate_early(const Eigen::VectorXd& u, ShellState& state, bool with_pressure) const {
  state.early = true;
  return evaluate_rule(early_, u, state, with_pressure, false);
}

bool NonlinearShell::evaluate_rule(const Rule& rule, const Eigen::VectorXd& u, ShellState& state,
                                   bool with_pressure, bool with_points) const {
  const int32_t ndof = num_dofs();
  if (u.size() != ndof) fail(ErrorCode::kInvalidArgument, "nonlinear shell: the displacement must have 3n entries");
  state.displacement = u;
  if (with_points) {
    state.points.resize(kState * rule.points);
  } else {
    state.points.clear();  // (keeps its capacity for the next evaluation with them)
  }
  const size_t ne = rule.elements.size();
  const size_t rows = rule.element_rows.back();
  Workspace force_rows = take_workspace(3 * rows, true);
  Workspace pressure_rows = with_pressure ? take_workspace(3 * rows, true) : nullptr;
  std::vector<double> element_energy(ne, 0.0), element_gradient(ne, 0.0);
  std::vector<char> element_ok(ne, 1);
  for_each_element(rule, [&](size_t ei) {
    const Element& e = rule.elements[ei];
    const auto p = e.points;
    const auto m = static_cast<Eigen::Index>(e.indices.size());
    thread_local Eigen::MatrixX3d local;
    local.resize(m, 3);
    for (Eigen::Index a = 0; a < m; ++a) local.row(a) = u.segment<3>(3 * e.indices[static_cast<size_t>(a)]).transpose();
    Scratch& scratch = thread_scratch(rule, e);
    double* force = force_rows->data() + 3 * rule.element_rows[ei];
    double* pressure = with_pressure ? pressure_rows->data() + 3 * rule.element_rows[ei] : nullptr;
    std::fill(force, force + 3 * m, 0.0);
    if (with_pressure) std::fill(pressure, pressure + 3 * m, 0.0);
    double energy = 0.0, gradient = 0.0;
    element_ok[ei] = element_forces(scratch.pieces.data(), scratch.pieces.size(), p, m,
                                    local.data(), rule.reference.data() + kRef * e.first_point, bending(),
                                    with_points ? state.points.data() + kState * e.first_point : nullptr,
                                    with_pressure, scratch.values.data(), scratch.coef.data(), force, pressure,
                                    energy, gradient);
    element_energy[ei] = energy;
    element_gradient[ei] = gradient;
  });
  state.valid = std::all_of(element_ok.begin(), element_ok.end(), [](char ok) { return ok != 0; });
  state.energy = 0.0;
  state.max_gradient = ne ? *std::max_element(element_gradient.begin(), element_gradient.end()) : 0.0;
  state.internal_force.resize(ndof);
  state.pressure_force.resize(with_pressure ? ndof : 0);
  if (!state.valid) {
    state.internal_force.setZero();
    state.pressure_force.setZero();
    return false;
  }
  for (size_t ei = 0; ei < ne; ++ei) state.energy += element_energy[ei];
  for_each_control_point(rule, [&](int32_t c) {
    state.internal_force.segment<3>(3 * c) = Eigen::Vector3d(gathered(rule, force_rows->data(), 3, c, 0).data());
    if (with_pressure) {
      state.pressure_force.segment<3>(3 * c) = Eigen::Vector3d(gathered(rule, pressure_rows->data(), 3, c, 0).data());
    }
  });
  state.valid = std::isfinite(state.energy) && state.internal_force.allFinite() &&
                (!with_pressure || state.pressure_force.allFinite());
  return state.valid;
}

void NonlinearShell::tangent_product(const ShellState& state, double pressure, const Eigen::MatrixXd& v,
                                     Eigen::MatrixXd& out) const {
  tangent_product_rule(fine_, state, pressure, v, out);
}

bool NonlinearShell::evaluate_coarse(const Eigen::VectorXd& u, ShellState& coarse) const {
  if (!has_jacobian_rule()) fail(ErrorCode::kInternal, "nonlinear shell: no coarse rule");
  return evaluate_rule(coarse_, u, coarse, false);
}

void NonlinearShell::approximate_tangent_product(const ShellState& coarse, double pressure, const Eigen::VectorXd& v,
                                                 Eigen::VectorXd& out) const {
  const Workspace remainder_rows = element_products(coarse_, coarse, pressure, v);
  out.resize(num_dofs());
  const int* outer = coarse_error_.outerIndexPtr();
  const int* inner = coarse_error_.innerIndexPtr();
  const double* error = coarse_error_.valuePtr();
  const double* x = v.data();
  // Rows 3c..3c+2 of (K - K_coarse(0)) v, `c` and `d` side by side (six independent chains of
  // additions; each row's own order is that of a one-thread column-by-column product, as the
  // matrix is symmetric bit for bit and its columns 3c..3c+2 share their rows).
  auto rows_of = [&](int32_t c, int32_t d) {
    const int k = 3 * c, l = 3 * d;
    const int lk = outer[k + 1] - outer[k], ll = outer[l + 1] - outer[l];
    const int* rk = inner + outer[k];
    const int* rl = inner + outer[l];
    const double *k0 = error + outer[k], *k1 = error + outer[k + 1], *k2 = error + outer[k + 2];
    const double *l0 = error + outer[l], *l1 = error + outer[l + 1], *l2 = error + outer[l + 2];
    double a0 = 0.0, a1 = 0.0, a2 = 0.0, b0 = 0.0, b1 = 0.0, b2 = 0.0;
    const int both = std::min(lk, ll);
    int at = 0;
    for (; at < both; ++at) {
      const double xk = x[rk[at]], xl = x[rl[at]];
      a0 += k0[at] * xk;
      b0 += l0[at] * xl;
      a1 += k1[at] * xk;
      b1 += l1[at] * xl;
      a2 += k2[at] * xk;
      b2 += l2[at] * xl;
    }
    for (int i = at; i < lk; ++i) {
      const double xk = x[rk[i]];
      a0 += k0[i] * xk;
      a1 += k1[i] * xk;
      a2 += k2[i] * xk;
    }
    for (int i = at; i < ll; ++i) {
      const double xl = x[rl[i]];
      b0 += l0[i] * xl;
      b1 += l1[i] * xl;
      b2 += l2[i] * xl;
    }
    const std::array<double, 3> rc = gathered(coarse_, remainder_rows->data(), 3, c, 0);
    out[k] = a0 + rc[0];
    out[k + 1] = a1 + rc[1];
    out[k + 2] = a2 + rc[2];
    if (d != c) {
      const std::array<double, 3> rd = gathered(coarse_, remainder_rows->data(), 3, d, 0);
      out[l] = b0 + rd[0];
      out[l + 1] = b1 + rd[1];
      out[l + 2] = b2 + rd[2];
    }
  };
  for_each_control_point_range(coarse_, [&](int32_t begin, int32_t end) {
    for (int32_t c = begin; c < end; c += 2) rows_of(c, std::min(c + 1, end - 1));
  });
}

NonlinearShell::Workspace NonlinearShell::element_products(const Rule& rule, const ShellState& state, double pressure,
                                                           const Eigen::MatrixXd& v) const {
  const int32_t ndof = num_dofs();
  if (!state.valid || v.rows() != ndof || state.points.size() != kState * rule.points) {
    fail(ErrorCode::kInternal, "nonlinear shell: tangent product of a bad state");
  }
  const Eigen::Index cols = v.cols();
  Workspace rows = take_workspace(static_cast<size_t>(3 * cols) * rule.element_rows.back(), true);
  for_each_element(rule, [&](size_t ei) {
    const Element& e = rule.elements[ei];
    const auto p = e.points;
    const auto m = static_cast<Eigen::Index>(e.indices.size());
    thread_local Eigen::MatrixX3d local;
    local.resize(m, 3);
    Scratch& scratch = thread_scratch(rule, e);
    double* result = rows->data() + static_cast<Eigen::Index>(rule.element_rows[ei]) * 3 * cols;
    std::fill(result, result + 3 * cols * m, 0.0);
    for (Eigen::Index col = 0; col < cols; ++col) {
      for (Eigen::Index a = 0; a < m; ++a) local.row(a) = v.block<3, 1>(3 * e.indices[static_cast<size_t>(a)], col).transpose();
      element_tangent(scratch.pieces.data(), scratch.pieces.size(), p, m, local.data(),
                      rule.reference.data() + kRef * e.first_point, bending(),
                      state.points.data() + kState * e.first_point, pressure, scratch.values.data(), scratch.coef.data(), result + 3 * col * m);
    }
  });
  return rows;
}

void NonlinearShell::tangent_product_rule(const Rule& rule, const ShellState& state, double pressure,
                                          const Eigen::MatrixXd& v, Eigen::MatrixXd& out) const {
  const Workspace rows = element_products(rule, state, pressure, v);
  const Eigen::Index cols = v.cols();
  out.resize(num_dofs(), cols);
  for_each_control_point(rule, [&](int32_t c) {
    for (Eigen::Index col = 0; col < cols; ++col) {
      out.block<3, 1>(3 * c, col) = Eigen::Vector3d(gathered(rule, rows->data(), 3 * cols, c, 3 * col).data());
    }
  });
}

void NonlinearShell::assemble_tangent(const ShellState& state, double pressure, Eigen::SparseMatrix<double>& out) const {
  assemble_rule(fine_, state, pressure, out);
}

bool NonlinearShell::assemble_jacobian(const ShellState& state, double pressure, Eigen::SparseMatrix<double>& out) const {
  if (!has_jacobian_rule()) {
    assemble_rule(fine_, state, pressure, out);
    return true;
  }
  ShellState coarse;
  if (!evaluate_rule(coarse_, state.displacement, coarse, false)) return false;
  assemble_approximate_tangent(coarse, pressure, out);
  return true;
}

Eigen::VectorXd NonlinearShell::approximate_force_change(const ShellState& from, const ShellState& to) const {
  if (!has_jacobian_rule()) fail(ErrorCode::kInternal, "nonlinear shell: no coarse rule");
  Eigen::VectorXd change = coarse_error_ * (to.displacement - from.displacement);
  change += to.internal_force - from.internal_force;
  return change;
}

// T_coarse + (K - K_coarse(0)) value by value: both are on K's pattern (assemble_rule).
void NonlinearShell::assemble_approximate_tangent(const ShellState& coarse, double pressure,
                                                  Eigen::SparseMatrix<double>& out) const {
  assemble_rule(coarse_, coarse, pressure, out);
  const double* error = coarse_error_.valuePtr();
  double* v = out.valuePtr();
  for (Eigen::Index i = 0; i < out.nonZeros(); ++i) v[i] += error[i];
}

void NonlinearShell::assemble_rule(const Rule& rule, const ShellState& state, double pressure,
                                   Eigen::SparseMatrix<double>& out) const {
  if (!state.valid || state.points.size() != kState * rule.points) {
    fail(ErrorCode::kInternal, "nonlinear shell: tangent of a bad state");
  }
  const Eigen::SparseMatrix<double>& k = model_->stiffness();
  out = k;  // the pattern; values overwritten below
  std::fill(out.valuePtr(), out.valuePtr() + out.nonZeros(), 0.0);
  // The element matrices, side by side in a workspace kept for the next assembly (fresh pages for
  // them cost more than computing them, on virtual machines).
  std::vector<size_t> at(rule.elements.size() + 1, 0);
  for (size_t ei = 0; ei < rule.elements.size(); ++ei) {
    const auto dofs = 3 * rule.elements[ei].indices.size();
    at[ei + 1] = at[ei] + dofs * dofs;
  }
  Workspace workspace = take_workspace(at.back());
  double* element_k = workspace->data();
  for_each_element(rule, [&](size_t ei) {
    const Element& e = rule.elements[ei];
    const auto m = static_cast<Eigen::Index>(e.indices.size());
    thread_local Eigen::MatrixXd ke;
    element_tangent_matrix(element_basis(rule, e), e.points, m, rule.reference.data() + kRef * e.first_point,
                           bending(), state.points.data() + kState * e.first_point, pressure, ke);
    std::copy(ke.data(), ke.data() + ke.size(), element_k + at[ei]);
  });
  // Column block 3b..3b+2 of K from the elements touching control point b, in element order:
  // each entry's sum in the order of a one-thread element-by-element assembly.
  for_each_control_point(rule, [&](int32_t b) {
    const auto bi = static_cast<size_t>(b);
    for (size_t t = rule.touch_start[bi]; t < rule.touch_start[bi + 1]; ++t) {
      const auto ei = static_cast<size_t>(rule.touches[t][0]);
      const Eigen::Index bl = rule.touches[t][1];
      const Element& e = rule.elements[ei];
      const auto m = static_cast<Eigen::Index>(e.indices.size());
      const Eigen::Map<const Eigen::MatrixXd> ke(element_k + at[ei], 3 * m, 3 * m);
      for (int j = 0; j < 3; ++j) {
        double* column = out.valuePtr() + out.outerIndexPtr()[3 * b + j];
        for (Eigen::Index al = 0; al < m; ++al) {
          double* block = column + e.offsets[static_cast<size_t>(al + m * bl)];
          for (int i = 0; i < 3; ++i) block[i] += ke(3 * al + i, 3 * bl + j);
        }
      }
    }
  });
}

}  // namespace softshell::engine::internal
