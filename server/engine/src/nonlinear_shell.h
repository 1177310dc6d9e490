#pragma once
// The geometrically nonlinear Kirchhoff-Love shell (private to the engine): total Lagrangian,
// exact Green-Lagrange membrane strains and the exact change of curvature of the deformed limit
// surface (Kiendl et al. 2009/2015), St. Venant-Kirchhoff material.
//
// Same quadrature points and weights, basis and material matrices as the linear model
// (kirchhoff_love.h), so its first-order term is K: at u = 0 the internal forces vanish and the
// tangent is K to round-off. The basis (N and its first and second derivatives) is evaluated once
// per model and kept here; a solve only recomputes the deformed frames.
//
// Per quadrature point, with A_a the reference tangents, a_a = A_a + u,a the deformed ones,
// n the deformed unit normal:
//   membrane strain  e = [1/2 (a1.a1 - A1.A1), 1/2 (a2.a2 - A2.A2), a1.a2 - A1.A2]
//   curvature change k = [B11 - b11, B22 - b22, 2 (B12 - b12)],   b_ab = a_a,b . n
//   energy density   1/2 e^T (t C) e + 1/2 k^T (t^3/12 C) k,  C the reference contravariant matrix
// Strains are computed from u,a and the reference frame without subtracting large numbers, so
// small deformations keep their relative accuracy.

#include <array>
#include <cstdint>
#include <functional>
#include <mutex>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "softshell/engine/shell_model.h"
#include "softshell/executor.h"

namespace softshell::engine::internal {

/// The deformed state of the shell at a displacement: per-point frames and stress resultants
/// (what tangent products need), strain energy and internal forces.
struct ShellState {
  Eigen::VectorXd displacement;    ///< 3n
  bool valid = false;              ///< false: some area element is zero, inverted or not finite
  double energy = 0.0;             ///< strain energy (J)
  Eigen::VectorXd internal_force;  ///< 3n: f_int = dW/du (N)
  /// 3n: the follower pressure force per unit pressure, integral of N_A n da over the deformed
  /// surface (zero-sized unless asked for).
  Eigen::VectorXd pressure_force;
  /// Largest displacement gradient |u,a| / |A_a| over the points: the internal forces are
  /// accurate to about eps E t h times it (round-off of strains that cancel in a rotation).
  double max_gradient = 0.0;
  /// Per quadrature point, kState doubles (nonlinear_element.h); empty unless evaluated with them.
  std::vector<double> points;
  bool has_points() const { return !points.empty(); }
  /// Evaluated on the early rule (NonlinearShell::evaluate_early), not the model's.
  bool early = false;
};

class NonlinearShell {
 public:
  /// Evaluates the basis at every quadrature point of `model` (the points and weights its K was
  /// integrated with). The per-element work runs on `executor` (empty: softshell::default_executor()),
  /// on at most `threads` of its threads (0 = all of them). `jacobian_gauss_points` > 0 adds a
  /// second, coarse rule (that many Gauss points per direction on every (sub-)face, no
  /// refinement) for `assemble_jacobian`: a tangent at the current state at a fraction of the
  /// cost, for the solver's linear solves (the answer's residual always uses the model's rule).
  /// `early_rule_levels` >= 0 adds a third rule, the model's with that many refinement levels
  /// toward extraordinary vertices (if that saves a third of the points or more): forces a few
  /// times cheaper and 1e-5..1e-4 of the forces off the model's, for Newton's first iterations.
  static std::shared_ptr<const NonlinearShell> build(std::shared_ptr<const ShellModel> model, int threads = 0,
                                                     int jacobian_gauss_points = 0,
                                                     std::shared_ptr<Executor> executor = nullptr,
                                                     int early_rule_levels = -1);

  const ShellModel& model() const { return *model_; }
  int32_t num_dofs() const { return model_->num_dofs(); }
  size_t num_points() const { return fine_.points; }
  size_t memory_bytes() const;

  /// At most this many of the executor's threads for the per-element work (0 = all); small models
  /// use one.
  void set_threads(int threads) { threads_ = threads; }

  /// Evaluates the state at displacement `u` (3n). `with_pressure`: also the follower pressure
  /// force. `with_points`: also the per-point frames and stress resultants that tangents need
  /// (`has_points`); without them a pass writes a third of the bytes. Returns state.valid.
  bool evaluate(const Eigen::VectorXd& u, ShellState& state, bool with_pressure, bool with_points = true) const;
  /// The same on the early rule (no per-point data; `state.early` set). Needs has_early_rule().
  bool evaluate_early(const Eigen::VectorXd& u, ShellState& state, bool with_pressure) const;
  bool has_early_rule() const { return early_.points > 0; }
  size_t num_early_points() const { return early_.points; }

  /// out = (K_T(u) - pressure K_p(u)) v for the columns of v (3n x k): the derivative of
  /// f_int - pressure * f_p at the state (K_p: the load stiffness of the follower pressure).
  void tangent_product(const ShellState& state, double pressure, const Eigen::MatrixXd& v, Eigen::MatrixXd& out) const;

  /// The assembled tangent K_T(u) - pressure sym(K_p(u)) on the sparsity pattern of the model's
  /// K (full symmetric, CSC). The load stiffness of a pressure is not symmetric on an open
  /// surface; its symmetric part is what a Cholesky factor can take.
  void assemble_tangent(const ShellState& state, double pressure, Eigen::SparseMatrix<double>& out) const;

  /// The approximate tangent J~ below, assembled (the exact tangent if there is no coarse rule):
  /// the preconditioner's matrix. Returns false if the state is degenerate at a coarse point.
  bool assemble_jacobian(const ShellState& state, double pressure, Eigen::SparseMatrix<double>& out) const;
  bool has_jacobian_rule() const { return coarse_.points > 0; }

  /// The approximate tangent the Newton directions are solved with (needs the coarse rule):
  ///   J~(u) = K + (K_T,coarse(u) - K_coarse(0)),
  /// the model's exact K plus the nonlinear remainder integrated with the coarse rule. It is K at
  /// rest and differs from the exact tangent only by the coarse rule's error on the remainder, so
  /// Newton on it converges nearly as fast, while a product costs a pass over the coarse points
  /// (far fewer than the model's where extraordinary vertices are refined) and one sparse product
  /// (with K - K_coarse(0), kept).
  /// `coarse` is the state at the same displacement on the coarse rule (`evaluate_coarse`).
  bool evaluate_coarse(const Eigen::VectorXd& u, ShellState& coarse) const;
  void approximate_tangent_product(const ShellState& coarse, double pressure, const Eigen::VectorXd& v,
                                   Eigen::VectorXd& out) const;
  /// The change of the internal forces the approximate model predicts from coarse state `from` to
  /// coarse state `to`: K s + (f_coarse(to) - f_coarse(from)) - K_coarse(0) s, s the step between
  /// them (the model's linear part exact, the nonlinear remainder on the coarse rule).
  Eigen::VectorXd approximate_force_change(const ShellState& from, const ShellState& to) const;
  /// J~ at `coarse`, assembled on the pattern of the model's K.
  void assemble_approximate_tangent(const ShellState& coarse, double pressure, Eigen::SparseMatrix<double>& out) const;

 private:
  // A run of an element's points. Where the run is one cell of the quadrature (n x n Gauss points
  // on a square) inside one polynomial piece of the limit surface (a regular patch, or a
  // sub-patch of an extraordinary face's patch tree), its basis is exactly the rule's bicubic
  // Bernstein basis at the cell's points times 16 x m coefficients: 1/6 of the weights to store
  // and stream through memory, the bottleneck of a pass over the points. Other runs keep them.
  struct Piece {
    Eigen::Index first = 0;   // first point within the element
    Eigen::Index points = 0;
    double size = 0.0;        // > 0: w holds Bernstein coefficients (16 x m) on a cell of this edge length
    int gauss = 0;            // and the cell has gauss x gauss points
    Eigen::MatrixXd w;        // otherwise the weights, 6 points x m: row d * points + q
  };
  struct Element {
    std::vector<int32_t> indices;  // m control points
    std::vector<Piece> pieces;
    size_t first_point = 0;        // into the per-point arrays
    Eigen::Index points = 0;       // P
    std::vector<int32_t> offsets;  // m x m: where block (a, b) starts in K's column 3b
  };
  struct Rule {
    std::vector<Element> elements;
    std::vector<double> reference;  // per point, kPointReference doubles (see .cpp)
    size_t points = 0;
    // By Gauss points per direction g of the cells' rules (those it has):
    std::array<Eigen::MatrixXd, 11> bernstein;    // 6 g^2 x 16: the unit cell's bicubic basis at its points
    std::array<Eigen::MatrixXd, 11> bernstein_t;  // its transpose (the 16 values at a point contiguous)
    // Per-element results (forces, products) are written side by side, element e's m x width
    // block (column-major) from row `element_rows[e]` on, and summed per control point from the
    // elements that touch it in element order (`touches`, from `touch_start[p]` on): the order
    // one thread adds them in, so the sums are split among threads and keep their bits.
    std::vector<size_t> element_rows;                  // ne + 1
    std::vector<size_t> touch_start;                   // n + 1
    std::vector<std::array<int32_t, 2>> touches;       // (element, the point's index in it)
  };
  struct Cell {  // (face, sub-face) and its points
    int32_t face = 0, subface = 0;
    std::vector<std::array<double, 2>> uvs;
    std::vector<double> weights;
  };
  NonlinearShell() = default;
  using Workspace = std::unique_ptr<std::vector<double>, std::function<void(std::vector<double>*)>>;

  // `gauss`: the Gauss points per direction of the cells' rules (the face's first).
  void build_rule(const std::vector<Cell>& cells, const std::vector<int>& gauss, int threads, Rule& rule) const;
  static Eigen::MatrixXd element_basis(const Rule& rule, const Element& e);  // 6P x m
  int pass_threads(const Rule& rule) const;  // the threads a pass over `rule` runs on
  template <class Fn>
  void for_each_element(const Rule& rule, Fn&& fn) const;
  // fn(p) for every control point p, on pass_threads(rule) threads.
  template <class Fn>
  void for_each_control_point(const Rule& rule, Fn&& fn) const;
  // fn(begin, end) for ranges of control points that cover them all.
  template <class Fn>
  void for_each_control_point_range(const Rule& rule, Fn&& fn) const;
  // Sums over the elements touching control point p of their columns k, k + 1, k + 2 at p,
  // per-element blocks of `width` columns in `rows` (Rule::element_rows).
  static std::array<double, 3> gathered(const Rule& rule, const double* rows, Eigen::Index width, int32_t p, Eigen::Index k);
  bool evaluate_rule(const Rule& rule, const Eigen::VectorXd& u, ShellState& state, bool with_pressure,
                     bool with_points = true) const;
  void tangent_product_rule(const Rule& rule, const ShellState& state, double pressure, const Eigen::MatrixXd& v,
                            Eigen::MatrixXd& out) const;
  // The elements' products with the columns of v, side by side (Rule::element_rows, width 3 v.cols()).
  Workspace element_products(const Rule& rule, const ShellState& state, double pressure,
                             const Eigen::MatrixXd& v) const;
  void assemble_rule(const Rule& rule, const ShellState& state, double pressure, Eigen::SparseMatrix<double>& out) const;

  std::shared_ptr<const ShellModel> model_;
  Rule fine_, coarse_, early_;
  // K minus K integrated with the coarse rule: the coarse rule's error on the linear part, which
  // the approximate model adds back (empty: no coarse rule).
  Eigen::SparseMatrix<double> coarse_error_;
  int workers(int requested) const;  // threads to use for `requested` (0 = all)
  // The bending matrix over the membrane one, t^2 / 12 (nonlinear_element.h).
  double bending() const {
    const double t = model_->material().thickness;
    return t * t / 12.0;
  }
  size_t count_bytes() const;
  size_t bytes_ = 0;  // memory_bytes(), counted when built

  std::shared_ptr<Executor> executor_;
  int threads_ = 0;

  // Workspaces of passes, returned to their pool when done (one per concurrent pass).
  // `rows`: a workspace for per-element rows (a few MB), kept apart from the element matrices'.
  Workspace take_workspace(size_t size, bool rows = false) const;
  mutable std::mutex workspace_mutex_;
  mutable std::vector<std::unique_ptr<std::vector<double>>> workspaces_, row_workspaces_;
};

}  // namespace softshell::engine::internal
