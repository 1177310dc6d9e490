// The nonlinear equilibrium solve: inexact Newton. Each Newton direction solves the exact tangent
// (applied matrix-free) by GMRES, preconditioned by a constrained solve on a factored tangent:
// the cached linear factor K at rest, later a tangent factored at a deformed state, refreshed
// when the Krylov iterations stop converging fast. Load steps, chosen by the solver, when one
// step is too large; a secant predictor between load steps and between the steps of a drag.
// Where Newton stalls far from an answer on an indefinite tangent (past a buckling load), or
// wanders near one (near an unstable state), trust-region steps on the potential energy until it
// is close to an answer. (About 850 lines: Newton, the trust region, the preconditioner refresh,
// the load stepping and the answer's check share one Run state; split, they would pass it
// around.)
//
// Why not quasi-Newton or chord steps on an older factor: in a thin shell such steps drift off
// the Newton path (a rotation linearized on the wrong tangent stretches the surface) and then
// need many iterations to come back; measured on the rigid-rotation and cantilever tests they
// took 3-10 times the iterations of Newton, or did not converge.
#include "softshell/engine/nonlinear_solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>
#include <thread>

#include "problem.h"
#include "factor_cache_impl.h"
#include "kkt_operator.h"
#include "krylov.h"
#include "load_path.h"
#include "nonlinear_shell.h"
#include "solver_testing.h"

namespace softshell::engine {
namespace internal {

std::atomic<FastPathCorruption> g_corrupt_nonlinear_answer{nullptr};
std::atomic<bool> g_directions_by_difference{false};
std::atomic<FastPathCorruption> g_corrupt_prediction{nullptr};
std::atomic<int> g_fail_load_steps{0};
std::atomic<LoadStepFilter> g_fail_load_step{nullptr};
std::atomic<DirectionSpoiler> g_spoil_newton_direction{nullptr};
std::atomic<int> g_tangent_product_delay_us{0};

// What a solve leaves for the next one that starts from its answer (the next step of a drag).
struct NonlinearMemory {
  Eigen::VectorXd end;                                        // the displacement it converged to
  Eigen::VectorXd end_force;                                  // the internal forces there (or empty)
  std::vector<int32_t> fixed;                                 // the problem's prescribed DOFs
  std::vector<std::vector<std::pair<int32_t, double>>> rows;  // the rows' terms
  std::shared_ptr<const Factorization> factor;                // the last preconditioner's factor
  std::shared_ptr<const Eigen::SparseMatrix<double>> matrix;  // and the matrix it factors
  bool factor_is_k = false;                                   // that matrix is the model's K
  int penalty_level = 0;                                      // constraint penalty it needed
  // For the predictor of the next step: the last answers of this drag (oldest first, `end`
  // last) with what each request asked (prescribed values, row values, loads).
  std::vector<std::pair<Eigen::VectorXd, Eigen::VectorXd>> history;  // (targets, displacement)
};

}  // namespace internal

namespace {

using internal::Factorization;
using internal::KktOperator;
using internal::NonlinearMemory;
using internal::NonlinearShell;
using internal::Problem;
using internal::Row;
using internal::ShellState;
using Clock = std::chrono::steady_clock;

double ms_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

std::string percent(double x) {
  std::ostringstream s;
  s.precision(3);
  s << 100.0 * x << "%";
  return s.str();
}

std::string scientific(double x) {
  std::ostringstream s;
  s.precision(2);
  s << std::scientific << x;
  return s.str();
}

constexpr int kMaxStepIterations = 30;     // Newton iterations per load step before it is split
constexpr int kMaxKrylov = 24;             // GMRES iterations per Newton step
constexpr int kMaxTrustSteps = 100;        // trust-region steps per load step
// With NonlinearOptions::reproducible, what a refresh of the preconditioner costs in Krylov
// iterations (refresh_if_slow): this many per factorization it took (a refresh past a buckling
// load tries up to seven), and before a request's first refresh kFirstRefreshCost, as the timed
// rule guesses. Timed, a refresh cost 15-20 Krylov iterations on catmark_righthanded and
// spot_quadrangulated (docs/benchmarks.md, seventeenth session).
constexpr int kRefreshCost = 20;
constexpr int kFirstRefreshCost = 2;
// Newton on the approximate directions that has come within kWanderBelow of an answer (with the
// rows met) and then not halved its best residual in kWanderIterations iterations, still above
// kTrustUntil, wanders near an unstable state (on spot_quadrangulated's drag, between 1e-5 and
// 1e-1 for 20-50 iterations, until the load step was split): trust-region steps on the energy
// take over, and stay on until the residual is below kTrustUntil. Far from an answer (above
// kWanderBelow) such stalls are the nonlinearity of large rotations, where Newton gets through
// and steps on the energy are slow (the flat plate's rigid turn by 180 degrees, docs/accuracy.md,
// was refused with the rule applied at any residual). Measured on bench_drag_paths
// (docs/benchmarks.md, sixteenth session).
constexpr int kWanderIterations = 4;
constexpr double kWanderBelow = 1e-2;
// Such a trust region hands back to Newton after a confirmed step inside the region only below
// this residual (on spot's drag, handing back after its first one, Newton's next step went back
// to residuals near 1).
constexpr double kTrustUntil = 1e-4;
// Intermediate load steps only give the next one its start (the answer is converged to the
// request's tolerance at the last step and checked there): 1% of the forces acting is close
// enough for Newton's next step. Measured from rest on catmark_righthanded: 19 Newton iterations
// instead of 24, 385-395 ms instead of 494-511 ms (1e-3: 22 iterations).
constexpr double kStepTolerance = 1e-2;
// The early rule (Run::early_) serves in the last load step while the relative out-of-balance
// force is above this (the Newton step from below it is evaluated on the model's rule), and for
// the whole of an intermediate one (kStepTolerance): its forces differ from the model's rule's by
// 1e-5..1e-4 of the forces acting (catmark_righthanded's drag, 2 levels against 6;
// docs/benchmarks.md).
constexpr double kEarlyRuleUntil = 1e-3;
constexpr double kMinLoadStep = 1.0 / 1024.0;
// A drag step's predicted state with more of the forces acting out of balance than this is not
// used (Run::run): measured on spot_quadrangulated's drag, where the predictions start at 0.65-0.99
// (catmark_righthanded's at 1e-3..0.7).
constexpr double kUselessPrediction = 0.5;
// The first load step turns the surface by about this much (radians) in the linear estimate:
// Newton converges from there in a few iterations, and later steps have a secant predictor.
constexpr double kStepRotation = 0.2;
// Exact directions after the approximate ones take their tangent products as differences of the
// internal forces while GMRES is asked for no more than this relative accuracy: one pass over the
// model's rule without its per-point data, where an exact product needs that data (a pass that
// writes it) and then a pass of its own. A difference is good to about 1e-6 of the product
// (measured on catmark_righthanded, bent, against the exact product).
constexpr double kDifferenceEta = 1e-5;

// One solve: a request, its problem, the state and the current preconditioner.
class Run {
 public:
  Run(std::shared_ptr<const ShellModel> model, const NonlinearShell& shell, FactorCache& cache,
      const NonlinearOptions& options, const DeformationRequest& request, const Eigen::VectorXd* initial,
      std::shared_ptr<const NonlinearMemory> memory);
  NonlinearSolution run();
  std::shared_ptr<const NonlinearMemory> memory_out() const { return memory_out_; }

 private:
  // The approximate directions read no per-point data of the model's rule: their passes skip it.
  bool evaluate(const Eigen::VectorXd& u, ShellState& state) {
    return evaluate(u, state, !approximate_ && !differences_);
  }
  bool evaluate(const Eigen::VectorXd& u, ShellState& state, bool with_points) {
    ++stats_.evaluations;
    const auto t0 = Clock::now();
    if (early_) ++stats_.early_evaluations;
    const bool ok = early_ ? shell_.evaluate_early(u, state, pressure_ != 0.0)
                           : shell_.evaluate(u, state, pressure_ != 0.0, with_points);
    stats_.evaluate_ms += ms_between(t0, Clock::now());
    return ok;
  }
  // R(u, lambda): the out-of-balance force of the homotopy from the initial state (lambda = 0,
  // where R vanishes) to the request (lambda = 1).
  Eigen::VectorXd residual(const ShellState& s, double lambda) const {
    Eigen::VectorXd r = lambda * problem_.load - s.internal_force;
    if (pressure_ != 0.0) r += lambda * pressure_ * s.pressure_force;
    if (lambda < 1.0) r += (1.0 - lambda) * r0_;
    return r;
  }
  double force_scale(const ShellState& s, double lambda) const {
    Eigen::VectorXd applied = lambda * problem_.load;
    if (pressure_ != 0.0) applied += lambda * pressure_ * s.pressure_force;
    if (lambda < 1.0) applied += (1.0 - lambda) * r0_;
    return std::max({applied.norm(), s.internal_force.norm(), force_floor_ * s.max_gradient, 1e-300});
  }
  // From the early rule to the model's: the current state evaluated again on the model's rule (the
  // factor and the coarse state, made at the same displacement, stay).
  void leave_early() {
    early_ = false;
    crossed_rules_ = true;
    const Eigen::VectorXd u = state_.displacement;
    if (!evaluate(u, state_)) {
      fail(ErrorCode::kInternal,
           "the nonlinear solve could not evaluate on the model's rule a state it had evaluated on the early rule");
    }
  }
  // The per-point data of exact tangents at the current state (evaluated again if it was left out).
  void ensure_points() {
    if (state_.has_points()) return;
    const Eigen::VectorXd u = state_.displacement;
    if (!evaluate(u, state_, true)) {
      fail(ErrorCode::kInternal, "the nonlinear solve could not evaluate a state it had evaluated before");
    }
  }
  Eigen::VectorXd row_residual(const Eigen::VectorXd& u, double lambda) const;
  bool rows_met(const Eigen::VectorXd& g, const Eigen::VectorXd& u) const;
  // J v: the exact tangent of the residual's negative at the current state, on free DOFs; by
  // forward difference of the forces if `by_difference` (kDifferenceEta).
  Eigen::VectorXd tangent_times(const Eigen::VectorXd& v, double lambda, bool by_difference = false);
  Eigen::VectorXd precondition(const Eigen::VectorXd& r) const {
    return kkt_->solve(r, Eigen::VectorXd::Zero(static_cast<Eigen::Index>(problem_.rows.size())));
  }
  bool newton_direction(const Eigen::VectorXd& r, const Eigen::VectorXd& g, double lambda, double eta,
                        Eigen::VectorXd& p);
  void use_linear_factor();
  void prepare_penalty();
  void refresh_tangent();
  // Refreshes when the Krylov iterations since the last refresh, beyond the two a solve on a
  // fresh factor needs, add up to what a new factor costs (rent or buy: never more than twice
  // the best choice in hindsight; the last solve's cost alone let a stale factor serve solve
  // after solve of 9-16 iterations each), or when the last solve took more than two thirds of
  // GMRES's budget: on a factor made at the current state it needs 1-3, so the factor is stale
  // here and the next solves nearby would be as slow (the trust region's CG, allowed twice as
  // many, is held to the same count). Measured on catmark_righthanded (docs/benchmarks.md): the
  // drag's step p95 83-87 ms instead of 108-115 ms, from rest 141 Krylov iterations instead of 160.
  // Costs are counted in Krylov iterations (kRefreshCost; NonlinearOptions::reproducible, the
  // default), so that the solver's path follows the requests only, or timed (the last solve's time
  // per iteration, the last refresh's time; a request's first refresh guessed at two iterations).
  void refresh_if_slow() {
    const bool stale = last_krylov_ > 2 * kMaxKrylov / 3;
    const bool dear = options_.reproducible
                          ? excess_krylov_ > refresh_cost_
                          : excess_krylov_ms_ > (refresh_ms_ > 0.0 ? refresh_ms_ : 2.0 * krylov_ms_);
    if (!fresh_ && last_krylov_ > 3 && (stale || dear)) refresh_tangent();
  }
  double first_step();
  Eigen::VectorXd predicted_path(const std::vector<std::pair<Eigen::VectorXd, Eigen::VectorXd>>& history) const;
  bool solve_step(double from, double lambda, double tolerance);
  void measure_miss(const ShellState& next);
  // Takes the step to `next` (evaluated at its displacement); `next` keeps the old state's arrays.
  void move_to(ShellState& next) {
    u_ = next.displacement;
    if (approximate_) measure_miss(next);
    // Across rules the change of the forces holds the rules' difference: no miss measured, and the
    // next iteration's speed judges nothing (solve_step).
    crossed_rules_ = next.early != state_.early;
    if (crossed_rules_) miss_.resize(0);
    std::swap(state_, next);
    fresh_ = false;
  }
  double check_answer(const Eigen::VectorXd& u);
  // NonlinearOptions::on_load_step, with what the load step from `from` to `to` added to `before`.
  void report_load_step(double from, double to, bool converged, const NonlinearStats& before,
                        Clock::time_point started) {
    NonlinearLoadStep step;
    step.from = from;
    step.to = to;
    step.converged = converged;
    step.iterations = stats_.iterations - before.iterations;
    step.trust_region_steps = stats_.trust_region_steps - before.trust_region_steps;
    step.krylov_iterations = stats_.krylov_iterations - before.krylov_iterations;
    step.factorizations = stats_.factorizations - before.factorizations;
    step.residuals = std::move(step_residuals_);
    step_residuals_.clear();
    step.ms = ms_between(started, Clock::now());
    options_.on_load_step(step);
  }
  [[noreturn]] void give_up(double lambda, const std::string& why) const;

  std::shared_ptr<const ShellModel> model_;
  const NonlinearShell& shell_;
  FactorCache& cache_;
  const NonlinearOptions& options_;
  Clock::time_point start_;
  Problem problem_;
  double pressure_ = 0.0;
  internal::Pins pins_;
  std::unique_ptr<internal::Reactions> reactions_;
  std::unique_ptr<internal::PrescribedPath> path_of_fixed_;
  Eigen::VectorXd u0_, r0_, d0_;
  // Of the current load step, for NonlinearOptions::on_load_step (emptied by report_load_step).
  std::vector<double> step_residuals_;
  Eigen::VectorXd targets_;  // prescribed values, row values and loads of the request
  std::vector<std::pair<Eigen::VectorXd, Eigen::VectorXd>> history_;  // of the drag this solve continues
  Eigen::VectorXd path_;     // predicted du / dlambda (empty: none)
  double length_ = 1.0, force_floor_ = 0.0;
  double reached_ = 0.0;  // the fraction of the request the load steps converged to so far
  std::shared_ptr<const NonlinearMemory> memory_in_, memory_out_;

  // Current state and preconditioner.
  Eigen::VectorXd u_;
  ShellState state_;
  std::unique_ptr<KktOperator> kkt_;
  std::shared_ptr<const Factorization> factor_;
  std::shared_ptr<const Eigen::SparseMatrix<double>> matrix_;
  bool factor_is_k_ = false;
  bool fresh_ = false;  // the factor was made at the current state
  std::vector<std::pair<int64_t, double>> penalty_;  // value index in the tangent, coefficient
  double penalty_unit_ = 0.0;
  int penalty_level_ = 0;
  int last_krylov_ = 0;
  // Krylov iterations since the last refresh beyond the two a fresh factor needs (refresh_if_slow),
  // timed and counted, and what the last refresh cost, timed and in Krylov iterations.
  double excess_krylov_ms_ = 0.0, krylov_ms_ = 0.0, refresh_ms_ = 0.0;
  int excess_krylov_ = 0, refresh_cost_ = kFirstRefreshCost;
  void count_krylov(int iterations, double ms) {
    stats_.krylov_iterations += iterations;
    stats_.krylov_ms += ms;
    last_krylov_ = iterations;
    if (iterations > 0) krylov_ms_ = ms / iterations;
    excess_krylov_ms_ += std::max(0, iterations - 2) * krylov_ms_;
    excess_krylov_ += std::max(0, iterations - 2);
  }
  double last_residual_ = 0.0;
  // Newton directions on the approximate tangent (NonlinearShell::approximate_tangent_product)
  // until Newton on it is slow because of the approximation; then on the exact one for the rest
  // of the load step (set at the start of each, solve_step).
  bool approximate_ = false;
  void start_approximate() {
    differences_ = internal::g_directions_by_difference.load();
    approximate_ = options_.approximate_directions && shell_.has_jacobian_rule() && !differences_;
    miss_.resize(0);
  }
  // Set where exact directions followed approximate ones in this load step: their products may be
  // differences of the forces (tangent_times), and its states leave out the per-point data.
  bool differences_ = false;
  // Set while the forces are evaluated on the shell's early rule (NonlinearShell::evaluate_early:
  // the model's rule with fewer levels at extraordinary vertices, a few times cheaper, its forces
  // 1e-5..1e-4 of the forces acting off the model's) in a request taken in several load steps:
  // for the whole of an intermediate load step (its tolerance, 1e-2, is far above what the rules
  // differ by), and in the last one until the out-of-balance force is below kEarlyRuleUntil. The
  // answer converges, and is checked, on the model's rule.
  bool early_ = false;
  bool crossed_rules_ = false;  // the last step went from one rule to the other (move_to)
  ShellState difference_state_;  // the state a difference is taken at, its arrays kept
  ShellState coarse_;  // the state on the coarse rule, at state_'s displacement (when approximate_)
  ShellState spare_, coarse_spare_;  // the last states replaced, their arrays reused by the next
  // Trust-region steps on the potential energy while Newton stalls far from an answer (past a
  // buckling load the tangent is indefinite and Newton jumps between branches) or wanders near one
  // (kWanderIterations): each minimizes the quadratic model of the energy in a region of the
  // preconditioner's norm (Steihaug's truncated CG, which follows a direction of negative
  // curvature to the region's edge) and is taken only if the energy falls as the model predicts,
  // so the iteration goes down to a stable equilibrium; a step inside the region that the energy
  // confirms hands back to Newton (where Newton wandered, only below kTrustUntil).
  bool trust_ = false;
  bool trust_stays_ = false;  // the trust region was entered where Newton wandered: on to kTrustUntil
  bool indefinite_ = false;  // the last refresh could not factor the tangent, only a shift of it
  double radius_ = 0.0;  // in the norm sqrt(p^T M p), M the factored preconditioner's matrix
  bool trust_region_step(const Eigen::VectorXd& r, double lambda);
  double potential(const ShellState& s, double lambda) const {
    double work = lambda * problem_.load.dot(s.displacement);
    if (lambda < 1.0) work += (1.0 - lambda) * r0_.dot(s.displacement);
    return s.energy - work;
  }
  // The last step's change of the internal forces minus the change the approximate model predicts
  // (empty: not measured), on the DOFs not prescribed.
  Eigen::VectorXd miss_;
  bool coarse_is_current() const {
    return coarse_.valid && coarse_.displacement.size() == state_.displacement.size() &&
           coarse_.displacement == state_.displacement;
  }
  NonlinearStats stats_;
};

Run::Run(std::shared_ptr<const ShellModel> model, const NonlinearShell& shell, FactorCache& cache,
         const NonlinearOptions& options, const DeformationRequest& request, const Eigen::VectorXd* initial,
         std::shared_ptr<const NonlinearMemory> memory)
    : model_(std::move(model)), shell_(shell), cache_(cache), options_(options), start_(Clock::now()),
      memory_in_(std::move(memory)) {
  const ShellModel& m = *model_;
  DeformationRequest dead = request;
  dead.pressure = 0.0;  // follows the deformed surface: handled here, not in the dead load
  problem_ = internal::build_problem(m, dead);
  internal::check_determined(m, problem_);
  pressure_ = request.pressure;
  pins_ = internal::choose_pins(m, problem_.fixed);
  reactions_ = std::make_unique<internal::Reactions>(problem_);
  const auto ndof = m.num_dofs();
  u0_ = Eigen::VectorXd::Zero(ndof);
  if (initial) {
    if (initial->size() != ndof) {
      fail(ErrorCode::kInvalidArgument, "the initial displacement has " + std::to_string(initial->size()) +
                                            " entries; the model has " + std::to_string(ndof) + " DOFs");
    }
    if (!initial->allFinite()) fail(ErrorCode::kInvalidArgument, "the initial displacement has a NaN or infinite entry");
    u0_ = *initial;
  }
  length_ = std::max(m.mesh().bounding_diagonal(), 1e-300);
  // Forces below floor * (largest displacement gradient) are round-off of the internal forces:
  // their absolute accuracy is about eps E t h per DOF times that gradient (measured: 1.3 eps
  // E t h sqrt(3n) for a rigid half turn), so 1e-6 leaves a margin of 30 over the tolerance.
  const Material& mat = m.material();
  const double h = std::sqrt(m.area() / std::max(1, m.mesh().num_faces()));
  force_floor_ = 1e-6 * mat.youngs_modulus * mat.thickness * h * std::sqrt(static_cast<double>(ndof));
}

Eigen::VectorXd Run::row_residual(const Eigen::VectorXd& u, double lambda) const {
  Eigen::VectorXd g(static_cast<Eigen::Index>(problem_.rows.size()));
  for (size_t k = 0; k < problem_.rows.size(); ++k) {
    double lhs = 0.0;
    for (const auto& [dof, coef] : problem_.rows[k].terms) lhs += coef * u[dof];
    const double start = d0_[static_cast<Eigen::Index>(k)];
    g[static_cast<Eigen::Index>(k)] = start + lambda * (problem_.rows[k].rhs - start) - lhs;
  }
  return g;
}

bool Run::rows_met(const Eigen::VectorXd& g, const Eigen::VectorXd& u) const {
  const double scale = std::max(u.cwiseAbs().maxCoeff(), 1e-9 * length_);
  for (size_t k = 0; k < problem_.rows.size(); ++k) {
    if (std::abs(g[static_cast<Eigen::Index>(k)]) > 1e-10 * problem_.rows[k].scale * scale) return false;
  }
  return true;
}

Eigen::VectorXd Run::tangent_times(const Eigen::VectorXd& v, double lambda, bool by_difference) {
  if (const int delay = internal::g_tangent_product_delay_us.load(); delay > 0) {
    std::this_thread::sleep_for(std::chrono::microseconds(delay));  // a test's slow host
  }
  Eigen::VectorXd jv;
  const double largest = by_difference ? v.cwiseAbs().maxCoeff() : 0.0;
  if (approximate_) {
    shell_.approximate_tangent_product(coarse_, lambda * pressure_, v, jv);
  } else if (largest > 0.0 && std::isfinite(largest)) {
    // No control point moves by more than sqrt(epsilon) of the object's size: the error of a
    // forward difference (the forces' curvature times the step) and its round-off balance there.
    const double h = 1.5e-8 * length_ / largest;
    ShellState& moved = difference_state_;
    // (A Krylov iteration's cost, not an evaluation of the model in the statistics.)
    if (!shell_.evaluate(u_ + h * v, moved, pressure_ != 0.0, false)) return tangent_times(v, lambda, false);
    jv = (moved.internal_force - state_.internal_force) / h;
    if (pressure_ != 0.0) jv -= (lambda * pressure_ / h) * (moved.pressure_force - state_.pressure_force);
  } else {
    ensure_points();
    Eigen::MatrixXd out;
    shell_.tangent_product(state_, lambda * pressure_, v, out);
    jv = out.col(0);
  }
  for (int32_t dof : problem_.fixed) jv[dof] = 0.0;
  return jv;
}

// One trust-region step from state_ (r its out-of-balance force, the energy's negative gradient on
// the free DOFs; the rows already met, and kept by the step): Steihaug-Toint CG on the tangent,
// preconditioned and measured by the current factor (positive definite: where the tangent was not,
// the factor is of its shift toward K), refreshed as for Newton's directions. Returns false when
// the region has shrunk to nothing.
bool Run::trust_region_step(const Eigen::VectorXd& r, double lambda) {
  // CG to a tenth of the force: far from an answer the region limits the step. A region that
  // stays on down to kTrustUntil (kWanderIterations) solves to the residual there (up to 1e-3),
  // as inexact Newton would.
  const double eta = trust_stays_ ? std::clamp(last_residual_, 1e-3, 0.1) : 0.1;
  if (!approximate_) ensure_points();
  refresh_if_slow();
  const KktOperator& norm = *kkt_;
  const Eigen::VectorXd zero_rows = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(problem_.rows.size()));
  const auto t0 = Clock::now();
  Eigen::VectorXd res = r, d = norm.solve(res, zero_rows), p = Eigen::VectorXd::Zero(r.size());
  for (int32_t dof : problem_.fixed) res[dof] = 0.0;
  double rz = res.dot(d);
  if (!(rz > 0.0)) return false;
  // The first region: the preconditioner's own step for this force, or the norm of the strain
  // energy if that is less (a step cannot release more than there is).
  if (radius_ == 0.0) radius_ = std::min(std::sqrt(rz), std::sqrt(2.0 * std::max(state_.energy, 0.0)));
  const double rz0 = rz;
  double pp = 0.0, pd = 0.0, dd = rz;  // p^T M p, p^T M d, d^T M d
  Eigen::VectorXd hp = Eigen::VectorXd::Zero(r.size());  // H p
  bool edge = false;
  int iterations = 0;
  for (int j = 0; j < 2 * kMaxKrylov; ++j) {
    const Eigen::VectorXd hd = tangent_times(d, lambda);
    ++iterations;
    const double curvature = d.dot(hd);
    const double alpha = curvature > 0.0 ? rz / curvature : 0.0;
    if (curvature <= 0.0 || pp + 2.0 * alpha * pd + alpha * alpha * dd >= radius_ * radius_) {
      // To the edge along d: tau >= 0 with |p + tau d|_M = radius.
      const double tau = (-pd + std::sqrt(std::max(0.0, pd * pd + dd * (radius_ * radius_ - pp)))) / dd;
      p += tau * d;
      hp += tau * hd;
      edge = true;
      break;
    }
    p += alpha * d;
    hp += alpha * hd;
    res -= alpha * hd;
    const Eigen::VectorXd z_next = norm.solve(res, zero_rows);
    const double rz_next = res.dot(z_next);
    pp += 2.0 * alpha * pd + alpha * alpha * dd;
    if (rz_next <= eta * eta * rz0) break;
    const double beta = rz_next / rz;
    pd = beta * (pd + alpha * dd);
    dd = rz_next + beta * beta * dd;
    d = z_next + beta * d;
    rz = rz_next;
  }
  count_krylov(iterations, ms_between(t0, Clock::now()));
  ++stats_.trust_region_steps;
  const double predicted = r.dot(p) - 0.5 * p.dot(hp);  // decrease of the quadratic model
  ShellState& trial = spare_;
  const Eigen::VectorXd ut = u_ + p;
  const bool valid = evaluate(ut, trial);
  const double actual = valid ? potential(state_, lambda) - potential(trial, lambda) : -1.0;
  const double ratio = predicted > 0.0 ? actual / predicted : -1.0;
  if (ratio > 0.1) {
    move_to(trial);
    if (ratio > 0.75 && edge) radius_ *= 2.0;
    // A step inside the region, confirmed: Newton again (where Newton wandered, near an answer).
    if (!edge && ratio > 0.75 && (!trust_stays_ || last_residual_ < kTrustUntil)) trust_ = trust_stays_ = false;
  } else {
    radius_ *= 0.25;
  }
  return radius_ > 1e-12 * std::sqrt(rz0);
}

void Run::use_linear_factor() {
  const ShellModel& m = *model_;
  FactorCache::Impl& cache = internal::FactorCacheAccess::impl(cache_);
  bool hit = true;
  std::shared_ptr<const Factorization> factor = cache.find_subset(m.id(), problem_.fixed, 96);
  if (!factor) {
    factor = cache.get(m.id(), problem_.fixed,
                       [&] { return std::make_shared<const Factorization>(m, problem_.fixed, pins_.dofs, pins_.motions); }, hit);
  }
  if (!hit) ++stats_.factorizations;
  factor_ = factor;
  matrix_ = std::shared_ptr<const Eigen::SparseMatrix<double>>(model_, &m.stiffness());
  factor_is_k_ = true;
  kkt_ = std::make_unique<KktOperator>(factor_, matrix_, problem_, true);
}

// Where the rows' normal matrices C^T C fall in the tangent's value array: adding rho C^T C to the
// tangent leaves the constrained solve unchanged (C z = g) and makes the matrix positive definite
// when only the constraints hold the shell stable (a grab holding a part that would otherwise
// buckle). Rows coupling control points K does not couple are left out.
void Run::prepare_penalty() {
  const Eigen::SparseMatrix<double>& k = model_->stiffness();
  auto position = [&](int32_t row, int32_t col) -> int64_t {
    const int* begin = k.innerIndexPtr() + k.outerIndexPtr()[col];
    const int* end = k.innerIndexPtr() + k.outerIndexPtr()[col + 1];
    const int* it = std::lower_bound(begin, end, row);
    return it != end && *it == row ? it - k.innerIndexPtr() : -1;
  };
  for (const Row& row : problem_.rows) {
    std::vector<std::pair<int64_t, double>> entries;
    bool fits = true;
    for (size_t i = 0; i < row.terms.size() && fits; ++i) {
      for (size_t j = 0; j < row.terms.size() && fits; ++j) {
        const int64_t at = position(row.terms[i].first, row.terms[j].first);
        fits = at >= 0;
        entries.push_back({at, row.terms[i].second * row.terms[j].second / (row.scale * row.scale)});
      }
    }
    if (fits) penalty_.insert(penalty_.end(), entries.begin(), entries.end());
  }
  double diagonal = 0.0;
  for (Eigen::Index d = 0; d < k.rows(); ++d) {
    if (!problem_.is_fixed[static_cast<size_t>(d)]) diagonal = std::max(diagonal, k.coeff(d, d));
  }
  penalty_unit_ = diagonal;
}

// A preconditioner made at the current state: the approximate tangent (K and the coarse rule's
// nonlinear remainder: the very operator of the approximate directions, so GMRES on them needs one
// iteration while the factor is fresh) if the shell has a coarse rule, else the exact tangent,
// factored; if it is not positive definite, first with the constraint penalty (from the level
// that worked last), then shifted toward K (an unstable state on the way, or past a buckling
// load): still a preconditioner, the Newton directions use their own tangent.
void Run::refresh_tangent() {
  const auto t0 = Clock::now();
  const int32_t factorizations_before = stats_.factorizations;
  auto matrix = std::make_shared<Eigen::SparseMatrix<double>>();
  if (shell_.has_jacobian_rule() && coarse_is_current()) {
    shell_.assemble_approximate_tangent(coarse_, pressure_, *matrix);  // the coarse state is at hand
  } else if (!shell_.assemble_jacobian(state_, pressure_, *matrix)) {
    ensure_points();
    shell_.assemble_tangent(state_, pressure_, *matrix);
  }
  std::shared_ptr<const Factorization> factor;
  const Factorization* pattern = factor_is_k_ ? nullptr : factor_.get();
  auto try_factor = [&] {
    ++stats_.factorizations;
    try {
      // (Its sweeps on the solve's threads: two on a large factor, unless the solve has one. They
      // read L rounded to single precision: a preconditioner need not be exact, and a sweep of a
      // large factor runs at the speed of memory.)
      factor = std::make_shared<const Factorization>(
          *matrix, problem_.fixed, pins_.dofs, pattern, Eigen::MatrixXd(),
          options_.threads == 1 ? nullptr : options_.executor ? options_.executor : default_executor(),
          internal::SweepPrecision::kSingle);
      return true;
    } catch (const internal::FactorizationFailed&) {
      return false;
    }
  };
  static constexpr double kLevels[] = {0.0, 1e-4, 1e-2, 1.0};
  double added = 0.0;
  for (int level = penalty_level_; level < 4 && !factor; ++level) {
    if (level > 0 && penalty_.empty()) break;
    const double rho = kLevels[level] * penalty_unit_;
    for (const auto& [at, coef] : penalty_) matrix->valuePtr()[at] += (rho - added) * coef;
    added = rho;
    if (try_factor()) penalty_level_ = level;
  }
  indefinite_ = !factor;  // even with the constraint penalty: the tangent itself is not definite
  // The shift goes in place, value by value: every tangent is assembled on K's pattern (a new
  // sparse matrix per shift faulted in fresh pages, 6% of spot_quadrangulated's page faults).
  const Eigen::SparseMatrix<double>& k = model_->stiffness();
  if (matrix->nonZeros() != k.nonZeros()) fail(ErrorCode::kInternal, "a tangent is not on the pattern of K");
  for (double shift : {1e-4, 1e-2, 1.0}) {
    if (factor) break;
    double* values = matrix->valuePtr();
    const double* k_values = k.valuePtr();
    for (Eigen::Index i = 0; i < k.nonZeros(); ++i) values[i] += shift * k_values[i];
    try_factor();
  }
  if (factor) {
    factor_ = factor;
    matrix_ = matrix;
    factor_is_k_ = false;
    kkt_ = std::make_unique<KktOperator>(factor_, matrix_, problem_, false);
  } else {
    use_linear_factor();
  }
  fresh_ = true;
  excess_krylov_ms_ = 0.0;
  excess_krylov_ = 0;
  refresh_ms_ = ms_between(t0, Clock::now());
  refresh_cost_ = kRefreshCost * std::max(1, stats_.factorizations - factorizations_before);
  stats_.tangent_ms += refresh_ms_;
}

// The Newton direction p: J p = r on the DOFs the rows leave free and C p = g. The particular part
// that meets the rows comes from the preconditioner's constrained solve; the rest from GMRES to a
// relative accuracy eta. If GMRES is slow, the preconditioner is refreshed at this state first.
bool Run::newton_direction(const Eigen::VectorXd& r, const Eigen::VectorXd& g, double lambda, double eta,
                           Eigen::VectorXd& p) {
  if (approximate_ && !coarse_is_current()) {
    if (!shell_.evaluate_coarse(state_.displacement, coarse_)) approximate_ = false;
  }
  const bool by_difference = differences_ && eta >= kDifferenceEta;
  if (approximate_) {
    ++stats_.approximate_iterations;
  } else if (by_difference) {
    ++stats_.difference_iterations;
  } else {
    ensure_points();
  }
  for (int attempt = 0; attempt < 2; ++attempt) {
    refresh_if_slow();
    const Eigen::VectorXd pc = g.isZero(0.0) ? Eigen::VectorXd::Zero(r.size())
                                             : kkt_->solve(Eigen::VectorXd::Zero(r.size()), g);
    Eigen::VectorXd rhs = r;
    if (!pc.isZero(0.0)) rhs -= tangent_times(pc, lambda, by_difference);
    const auto t0 = Clock::now();
    const internal::KrylovResult k = internal::gmres(
        [&](const Eigen::VectorXd& v) { return precondition(tangent_times(v, lambda, by_difference)); },
        precondition(rhs), eta, fresh_ ? 2 * kMaxKrylov : kMaxKrylov);
    count_krylov(k.iterations, ms_between(t0, Clock::now()));
    if (k.converged || (fresh_ && k.relative_residual < 0.5)) {
      p = pc + k.x;
      return true;
    }
    if (fresh_) return false;
    refresh_tangent();
  }
  return false;
}

// The predicted change of the answer from the last one of a drag to this request's, per unit
// load step: the answers so far as functions of the position along the drag, extrapolated by
// the polynomial through the last three (quadratic) or two (secant), when the requests lie on a
// line in the space of targets (a grab moved steadily); empty otherwise.
Eigen::VectorXd Run::predicted_path(const std::vector<std::pair<Eigen::VectorXd, Eigen::VectorXd>>& history) const {
  const Eigen::VectorXd& last = history.back().first;
  const Eigen::VectorXd ahead = targets_ - last;
  const double length = ahead.norm();
  if (!(length > 0.0) || history.size() < 2) return {};
  const Eigen::VectorXd direction = ahead / length;
  std::vector<double> position;  // along the drag, this request at `length`, the last at 0
  for (const auto& [t, u] : history) {
    const Eigen::VectorXd offset = t - last;
    const double along = offset.dot(direction);
    if ((offset - along * direction).norm() > 0.1 * std::max(std::abs(along), 1e-300 * length)) return {};
    position.push_back(along);
  }
  const size_t n = std::min<size_t>(3, history.size()), first = history.size() - n;
  // Lagrange weights at `length` through the last n points.
  Eigen::VectorXd predicted = Eigen::VectorXd::Zero(history.back().second.size());
  for (size_t i = first; i < history.size(); ++i) {
    double w = 1.0;
    for (size_t k = first; k < history.size(); ++k) {
      if (k == i) continue;
      const double gap = position[i] - position[k];
      if (!(std::abs(gap) > 1e-12 * length)) return {};
      w *= (length - position[k]) / gap;
    }
    predicted += w * history[i].second;
  }
  return predicted - history.back().second;
}

// The linear estimate of the whole request's displacement increment (one constrained solve on
// the current factor) and the first load step from the largest rotation it implies.
double Run::first_step() {
  const ShellModel& m = *model_;
  Eigen::VectorXd jump = Eigen::VectorXd::Zero(m.num_dofs());
  for (int32_t dof : problem_.fixed) jump[dof] = problem_.fixed_value[dof] - u0_[dof];
  const Eigen::VectorXd r = residual(state_, 1.0) - *matrix_ * jump;
  const Eigen::VectorXd du = kkt_->solve(r, row_residual(u0_, 1.0)) + jump;
  const double rotation = std::max(path_of_fixed_->largest_turn(), internal::largest_edge_rotation(m.mesh(), du));
  if (!std::isfinite(rotation)) return kMinLoadStep;
  return rotation > kStepRotation ? std::max(kMinLoadStep, kStepRotation / rotation) : 1.0;
}

bool Run::solve_step(double from, double lambda, double tolerance) {
  for (int left = internal::g_fail_load_steps.load(); left > 0;) {
    if (internal::g_fail_load_steps.compare_exchange_weak(left, left - 1)) return false;  // a test's failure
  }
  if (auto fail_this = internal::g_fail_load_step.load(); fail_this && fail_this(from, lambda)) return false;
  // Prescribed DOFs along their path; the state is already at u unless they moved (a drag
  // changes only rows).
  path_of_fixed_->apply(lambda, u_);
  // Each load step starts on the approximate tangent again: a slow iteration far from the last
  // step's answer says little about how good the approximation is near this one's. (Set before
  // the step's first evaluation, which then leaves out the per-point data.)
  start_approximate();
  // The early rule in the load steps of a request taken in several (every one starts far from its
  // answer), not in a request's only step: a drag step starts 1-3 iterations from where the
  // model's rule is needed, and switching there costs an evaluation more than it saves (measured
  // on catmark_righthanded's drag: 6.0 Newton iterations a step instead of 5.4).
  early_ = approximate_ && shell_.has_early_rule() && (lambda < 1.0 || stats_.load_steps > 1);
  crossed_rules_ = false;
  // The last load step's Krylov counts judged the factor at that step's states; this one judges
  // it by its own first solve (from rest on catmark_righthanded: 4 refreshes instead of 5, the
  // same iterations).
  last_krylov_ = 0;
  excess_krylov_ms_ = 0.0;
  excess_krylov_ = 0;
  if (state_.displacement.size() != u_.size() || state_.displacement != u_) {
    if (!evaluate(u_, state_)) return false;
    fresh_ = false;
  } else if (state_.early && !early_) {
    if (!evaluate(u_, state_)) return false;
  }
  const bool intermediate = lambda < 1.0;  // to kStepTolerance: an early state is close enough
  double first_out = 0.0, previous = 1.0, eta_cap = 1e-3;
  // The residuals of the last two iterations that started with the rows met (the stall test).
  double last_met = HUGE_VAL, before_met = HUGE_VAL;
  // The best residual of this load step and the iteration it was reached in (kWanderIterations).
  double best = HUGE_VAL;
  int best_it = 0;
  trust_ = trust_stays_ = false;
  radius_ = 0.0;
  int trust_steps = 0;
  for (int it = 0;; ++it) {
    if (options_.cancel && options_.cancel->load()) fail(ErrorCode::kCancelled, "the nonlinear solve was cancelled");
    if (options_.time_limit_seconds > 0.0 && ms_between(start_, Clock::now()) > 1e3 * options_.time_limit_seconds) {
      give_up(reached_, "its time limit of " + internal::format_number(options_.time_limit_seconds) +
                          " s ran out; residual " + scientific(last_residual_));
    }
    if (early_ && (!approximate_ || trust_)) leave_early();  // exact directions, trust region: the model's rule
    const Eigen::VectorXd r = residual(state_, lambda);
    const Eigen::VectorXd g = row_residual(u_, lambda);
    const double out = reactions_->out_of_balance(r).norm(), scale = force_scale(state_, lambda);
    const bool rows_ok = rows_met(g, u_);
    last_residual_ = out / scale;
    if (options_.on_load_step) step_residuals_.push_back(last_residual_);
    if (early_ && rows_ok && last_residual_ <= tolerance) {
      if (intermediate) return true;
      leave_early();
      continue;
    }
    if (last_residual_ <= tolerance && rows_ok) return true;
    if (it == 0) first_out = out;
    // A step that has not gained two orders of magnitude in 20 Newton iterations is too large;
    // trust-region steps go on while they lower the energy, up to kMaxTrustSteps.
    const int newton_steps = it - trust_steps;
    if (newton_steps >= kMaxStepIterations || trust_steps >= kMaxTrustSteps ||
        stats_.iterations >= options_.max_iterations || (!trust_ && newton_steps >= 20 && out > 1e-2 * first_out)) {
      return false;
    }
    ++stats_.iterations;
    // Forcing term: loose far from the answer, tight enough near it that the step lands below
    // the tolerance (Eisenstat-Walker-like, from the relative residual).
    const double res = last_residual_;
    // Stalled far from an answer (the residual not halved in two iterations on the rows) with an
    // indefinite tangent (refactored here to know; Newton's next direction uses that factor):
    // trust-region steps. (A conservative problem only: a follower pressure has no potential.)
    // A stall on a definite tangent is the nonlinearity of a large rotation, where Newton is
    // faster than steps on the energy (measured on the rigid turns of docs/accuracy.md).
    if (!trust_ && rows_ok && res > 1e-2 && res > 0.5 * before_met && pressure_ == 0.0) {
      if (!fresh_) refresh_tangent();
      trust_ = indefinite_;
      if (trust_ && early_) {
        leave_early();
        --stats_.iterations;  // this one computed no direction: the next does, on the model's rule
        continue;
      }
    }
    if (rows_ok) {
      before_met = last_met;
      last_met = res;
    }
    if (trust_) {
      previous = res;
      ++trust_steps;
      if (!trust_region_step(r, lambda)) return false;
      continue;
    }
    // Wandering near an unstable state (kWanderIterations): trust-region steps from the next
    // iteration on, on the model's rule. Newton gets kWanderIterations again when they hand back.
    if (rows_ok && res < 0.5 * best) {
      best = res;
      best_it = it;
    }
    if (approximate_ && rows_ok && pressure_ == 0.0 && best < kWanderBelow && res > kTrustUntil &&
        it - best_it >= kWanderIterations) {
      trust_ = true;
      trust_stays_ = true;
      best_it = it;
      --stats_.iterations;  // this one computed no direction
      continue;
    }
    // Thin shells need accurate Newton directions (measured: a flat plate turned rigidly needs
    // eta <= 1e-6, curved shells 1e-3): start at 1e-3 and tighten when Newton is slow. On the
    // approximate tangent, a slow iteration is blamed on what its residual is made of:
    //  - most of it is what the approximate model mispredicted over the last step: exact
    //    directions from here on;
    //  - next to nothing of it (the coarse rule is the model's own here, a mesh without refined
    //    cells): as on the exact tangent, tighter;
    //  - otherwise the nonlinearity, which neither would help: far from the answer Newton is slow
    //    on the exact tangent too, and an exact direction costs 5-10 times more (measured from
    //    rest on catmark_righthanded: 2.5 s switching at the first slow iteration, 1.2 s so).
    if (it > 0 && res > 0.2 * previous && !crossed_rules_) {
      const double missed = approximate_ && miss_.size() == r.size() ? reactions_->out_of_balance(miss_).norm() : 0.0;
      if (approximate_ && missed > 0.5 * out) {
        approximate_ = false;
        differences_ = true;
        if (early_) {
          leave_early();
          --stats_.iterations;  // as above
          continue;
        }
      } else if (!approximate_ || missed < 1e-3 * out) {
        eta_cap = std::max(1e-8, 0.01 * eta_cap);
      }
    }
    const double eta = std::clamp(std::max(std::min(res, res / previous), 0.3 * tolerance / res), 1e-9, eta_cap);
    previous = res;
    Eigen::VectorXd p;
    if (!newton_direction(r, rows_ok ? Eigen::VectorXd::Zero(g.size()) : g, lambda, eta, p)) return false;
    if (auto spoil = internal::g_spoil_newton_direction.load()) spoil(res, p);
    // The Newton step, whole: in a thin shell it often overshoots into large membrane forces
    // that the next step removes, so neither the force nor the energy is a useful merit. It is
    // shortened only if it folds the surface or multiplies the force a thousandfold.
    // A step from below kEarlyRuleUntil lands where the rules' difference would be most of what is
    // left: it is evaluated on the model's rule (and the iteration stays there).
    if (early_ && !intermediate && res <= kEarlyRuleUntil) early_ = false;
    ShellState& trial = spare_;  // its arrays reused: a state of the model's rule is tens of MB
    bool accepted = false;
    for (double alpha = 1.0; alpha > 1e-3 && !accepted; alpha *= 0.25) {
      const Eigen::VectorXd ut = u_ + alpha * p;
      if (!evaluate(ut, trial)) continue;
      const double out_t = reactions_->out_of_balance(residual(trial, lambda)).norm();
      accepted = out_t < 1e3 * std::max(out, 1e-6 * scale) || !rows_ok;
    }
    if (!accepted) return false;
    move_to(trial);
  }
}

// After a step from state_ to `next` on the approximate directions: the coarse state at `next`
// (the next direction needs it) and what the approximate model mispredicted of the step's change
// of the internal forces.
void Run::measure_miss(const ShellState& next) {
  miss_.resize(0);
  if (!coarse_is_current()) return;  // no coarse state at the step's start: nothing measured
  ShellState& coarse = coarse_spare_;
  if (!shell_.evaluate_coarse(next.displacement, coarse)) {
    approximate_ = false;
    return;
  }
  miss_ = (next.internal_force - state_.internal_force) - shell_.approximate_force_change(coarse_, coarse);
  for (int32_t dof : problem_.fixed) miss_[dof] = 0.0;
  std::swap(coarse_, coarse);
}

// The safety net, as on the linear solver's answers: before an answer leaves, the state it
// describes is checked against the request on its own terms (not the iteration's measure alone):
// finite, the prescribed DOFs as asked, the out-of-balance force of the nonlinear equilibrium
// (after the constraint reactions that best explain it) within the tolerance of the forces
// acting, and every constraint row within the allowance the linear check gives it (a share of the
// displacements, the geometry's round-off and the round-off of its terms). Returns the largest
// ratio residual / allowance (<= 1); refuses the answer otherwise.
double Run::check_answer(const Eigen::VectorXd& u) {
  // The same allowances as the linear check (solver.cpp); the equilibrium's is a margin over the
  // Newton tolerance, so that only a state that is not the converged one fails it.
  constexpr double kEquilibriumMargin = 10.0;
  const std::string refused = "the nonlinear solve produced no accurate answer: ";
  if (!u.allFinite()) fail(ErrorCode::kUnprocessable, refused + "the displacements are not finite");
  for (int32_t dof : problem_.fixed) {
    if (u[dof] != problem_.fixed_value[dof]) {
      fail(ErrorCode::kUnprocessable, refused + "control point " + std::to_string(dof / 3) + " (" +
                                          internal::axis_name(dof % 3) + ") is not where its vertex constraint puts it");
    }
  }
  ShellState checked;
  const ShellState* s = &state_;
  early_ = false;  // checked on the model's rule
  if (state_.displacement.size() != u.size() || state_.displacement != u || state_.early) {
    if (!evaluate(u, checked)) fail(ErrorCode::kUnprocessable, refused + "the answer folds the surface onto itself");
    s = &checked;
  }
  double worst = 0.0;
  Vec3 lo, hi;
  model_->mesh().bounding_box(lo, hi);
  const double size = std::max({(hi - lo).norm(), lo.cwiseAbs().maxCoeff(), hi.cwiseAbs().maxCoeff()});
  double displacement_scale = u.cwiseAbs().maxCoeff();
  for (const Row& row : problem_.rows) displacement_scale = std::max(displacement_scale, std::abs(row.rhs) / row.scale);
  for (const Row& row : problem_.rows) {
    const auto [residual, allowed] = internal::check_row(row, u, displacement_scale, size);
    worst = std::max(worst, residual / allowed);
    if (!(residual <= allowed)) {
      fail(ErrorCode::kUnprocessable, refused + row.source + " is off by " + internal::format_number(residual) +
                                          " (displacements of " + internal::format_number(displacement_scale) +
                                          ")");
    }
  }
  const double equilibrium = reactions_->out_of_balance(residual(*s, 1.0)).norm() / force_scale(*s, 1.0);
  worst = std::max(worst, equilibrium / (kEquilibriumMargin * options_.tolerance));
  if (!(worst <= 1.0)) {
    fail(ErrorCode::kUnprocessable, refused + "the out-of-balance force is " + scientific(equilibrium) +
                                        " of the forces acting (allowed " +
                                        scientific(kEquilibriumMargin * options_.tolerance) + ")");
  }
  return worst;
}

void Run::give_up(double lambda, const std::string& why) const {
  std::string message = "the nonlinear model could not bring the shell to equilibrium: ";
  // (Short of the request's end, load steps converge only to kStepTolerance, as run() asks: the
  // fraction says how far the homotopy got, not where an equilibrium path ends.)
  message += lambda > 0.0 ? "it reached " + percent(lambda) + " of the requested loads and displacements to within " +
                                percent(std::max(kStepTolerance, options_.tolerance)) + " of equilibrium (" + why + ")"
                          : why;
  message += ". The shell may snap through or buckle under this request, or the load may exceed what it carries. "
             "Try a smaller step (drag in smaller increments, starting each from the previous answer), a smaller load, "
             "more supports, or the linear model";
  fail(ErrorCode::kUnprocessable, message);
}

NonlinearSolution Run::run() {
  const ShellModel& m = *model_;
  const auto ndof = m.num_dofs();
  u_ = u0_;
  const NonlinearMemory* mem = memory_in_.get();
  const bool continues = mem && mem->end.size() == ndof && mem->end == u0_;
  path_of_fixed_ = std::make_unique<internal::PrescribedPath>(m.mesh(), problem_, u0_);
  d0_.resize(static_cast<Eigen::Index>(problem_.rows.size()));
  for (size_t k = 0; k < problem_.rows.size(); ++k) {
    double lhs = 0.0;
    for (const auto& [dof, coef] : problem_.rows[k].terms) lhs += coef * u0_[dof];
    d0_[static_cast<Eigen::Index>(k)] = lhs;
  }
  prepare_penalty();

  // Preconditioner: the last one of a solve with the same prescribed DOFs (a drag), unless this
  // solve starts at rest, where K is the tangent.
  std::vector<std::vector<std::pair<int32_t, double>>> row_terms;
  for (const Row& row : problem_.rows) row_terms.push_back(row.terms);
  const bool at_rest = u0_.isZero(0.0);
  if (mem && !at_rest && mem->fixed == problem_.fixed && mem->factor && mem->factor->pinned() == pins_.dofs &&
      !mem->factor_is_k) {
    factor_ = mem->factor;
    matrix_ = mem->matrix;
    kkt_ = std::make_unique<KktOperator>(factor_, matrix_, problem_, false);
    if (mem->rows == row_terms) penalty_level_ = mem->penalty_level;
  } else {
    use_linear_factor();
    fresh_ = at_rest;
  }

  // The request's targets; a drag continuing the last solve in the same direction gets a secant
  // predictor (the last step's change, scaled to this one).
  const auto nf = static_cast<Eigen::Index>(problem_.fixed.size()), nr = static_cast<Eigen::Index>(problem_.rows.size());
  targets_.resize(nf + nr + ndof + 1);
  for (Eigen::Index k = 0; k < nf; ++k) targets_[k] = problem_.fixed_value[problem_.fixed[static_cast<size_t>(k)]];
  for (Eigen::Index k = 0; k < nr; ++k) targets_[nf + k] = problem_.rows[static_cast<size_t>(k)].rhs;
  targets_.segment(nf + nr, ndof) = problem_.load;
  targets_[nf + nr + ndof] = pressure_;
  const bool same_drag = continues && mem->rows == row_terms && mem->fixed == problem_.fixed &&
                         !mem->history.empty() && mem->history.back().first.size() == targets_.size();
  if (same_drag) path_ = predicted_path(mem->history);
  history_ = same_drag ? mem->history : decltype(history_){};
  if (!same_drag && at_rest) history_.push_back({Eigen::VectorXd::Zero(targets_.size()), u0_});  // rest answers the empty request

  Eigen::VectorXd discarded_path;  // a prediction not used (below), kept for a last attempt
  if (path_.size() == ndof && mem->end_force.size() == ndof) {
    // A drag step with a predictor evaluates its predicted state first, not this one: the last
    // answer's forces (one evaluation of the model's rule of the 6-7 a step costs).
    r0_ = mem->end_force;
    // The predicted state, evaluated as the step's first iteration would. A prediction that
    // leaves most of the forces acting out of balance predicts nothing (past a buckling load the
    // extrapolated shape can be on no branch at all): the step goes from the last answer instead,
    // evaluated again (one evaluation more).
    if (auto corrupt = internal::g_corrupt_prediction.load()) corrupt(path_);
    Eigen::VectorXd predicted = u0_ + path_;
    path_of_fixed_->apply(1.0, predicted);
    start_approximate();
    const bool useful = evaluate(predicted, state_) && reactions_->out_of_balance(residual(state_, 1.0)).norm() <=
                                                           kUselessPrediction * force_scale(state_, 1.0);
    stats_.prediction = useful ? NonlinearStats::Prediction::kUsed : NonlinearStats::Prediction::kDiscarded;
    if (!useful) {
      discarded_path = std::move(path_);
      path_.resize(0);
      if (!evaluate(u_, state_)) {
        fail(ErrorCode::kInternal, "the nonlinear solve could not evaluate its last answer again");
      }
    }
  } else {
    start_approximate();  // as the first load step will: no per-point data unless it needs them
    if (!evaluate(u_, state_)) {
      fail(ErrorCode::kInvalidArgument,
           "the initial displacement folds the surface onto itself (a zero or inverted area element)");
    }
    r0_ = state_.internal_force;
  }
  double lambda = 0.0, step = path_.size() == ndof ? 1.0 : first_step();
  std::vector<std::pair<double, Eigen::VectorXd>> converged{{0.0, u_}};
  while (lambda < 1.0) {
    const double target = std::min(1.0, lambda + step);
    const Eigen::VectorXd u_start = u_;
    ++stats_.load_steps;
    if (converged.size() >= 2) {  // secant through the last two converged load steps
      const auto& [l1, u1] = converged[converged.size() - 2];
      const auto& [l2, u2] = converged.back();
      path_ = (u2 - u1) / (l2 - l1);
    }
    if (path_.size() == ndof) u_ = u_start + (target - lambda) * path_;
    const NonlinearStats before = stats_;
    const auto step_start = Clock::now();
    const bool converged_step =
        solve_step(lambda, target, target < 1.0 ? std::max(kStepTolerance, options_.tolerance) : options_.tolerance);
    if (options_.on_load_step) report_load_step(lambda, target, converged_step, before, step_start);
    if (converged_step) {
      lambda = target;
      reached_ = std::max(reached_, target);
      step = std::min(1.0, 2.0 * step);
      converged.push_back({lambda, u_});
      continue;
    }
    // Half the failed load step, not half the nominal step: after a run of converged steps the
    // nominal step can be several times what was left to the request's end, and halving it
    // repeated the very same load step (traced on spot_quadrangulated's drag: 32 of 60 failed
    // load steps were such repeats, four or more in a row at its limit points).
    u_ = u_start;
    step = 0.5 * (target - lambda);
    if (stats_.iterations >= options_.max_iterations) {
      give_up(reached_, "the iteration limit of " + std::to_string(options_.max_iterations) + " was reached; residual " +
                            scientific(last_residual_));
    }
    if (step < kMinLoadStep || stats_.load_steps >= options_.max_load_steps) {
      if (discarded_path.size() == ndof && stats_.load_steps < options_.max_load_steps) {
        // Before refusing the step: from the prediction it discarded after all, in one load step
        // (and halved from there), within what is left of the request's budgets.
        path_ = std::move(discarded_path);
        discarded_path.resize(0);
        stats_.prediction = NonlinearStats::Prediction::kUsedAfterAll;
        lambda = 0.0;
        step = 1.0;
        converged.assign(1, {0.0, u0_});
        u_ = u0_;
        fresh_ = false;
        continue;
      }
      give_up(reached_, "it did not converge in steps of " + percent(step * 2.0) + " of the request; residual " +
                            scientific(last_residual_));
    }
    if (!evaluate(u_, state_)) give_up(lambda, "internal error: a converged state became invalid");
    fresh_ = false;
  }
  NonlinearSolution solution;
  solution.displacement = u_;
  for (int32_t dof : problem_.fixed) solution.displacement[dof] = problem_.fixed_value[dof];
  if (auto corrupt = internal::g_corrupt_nonlinear_answer.load()) corrupt(solution.displacement);
  const double check_ratio = check_answer(solution.displacement);
  solution.stats = stats_;
  solution.stats.check_ratio = check_ratio;
  solution.stats.residual = last_residual_;
  solution.stats.strain_energy = state_.energy;
  solution.stats.solve_ms = ms_between(start_, Clock::now());

  auto out = std::make_shared<NonlinearMemory>();
  out->end = solution.displacement;
  if (state_.displacement.size() == ndof && state_.displacement == solution.displacement && !state_.early) {
    out->end_force = state_.internal_force;
  }
  out->fixed = problem_.fixed;
  out->rows = std::move(row_terms);
  out->factor = factor_;
  out->matrix = matrix_;
  out->factor_is_k = factor_is_k_;
  out->penalty_level = penalty_level_;
  out->history = std::move(history_);
  out->history.push_back({targets_, solution.displacement});
  if (out->history.size() > 3) out->history.erase(out->history.begin());
  memory_out_ = std::move(out);
  return solution;
}

}  // namespace

NonlinearSolver::NonlinearSolver(std::shared_ptr<const ShellModel> model, std::shared_ptr<FactorCache> cache,
                                 NonlinearOptions options)
    : model_(std::move(model)), cache_(std::move(cache)), options_(options) {
  if (!model_) fail(ErrorCode::kInvalidArgument, "NonlinearSolver needs a model");
  if (!cache_) cache_ = std::make_shared<FactorCache>();
  if (!(options_.tolerance > 0.0) || options_.tolerance >= 1.0 || options_.max_iterations < 1 ||
      options_.max_load_steps < 1 || options_.tangent_gauss_points < 0 || options_.tangent_gauss_points > 10 ||
      options_.early_rule_levels < -1 || options_.early_rule_levels > 8 ||
      !(options_.time_limit_seconds >= 0.0) || !std::isfinite(options_.time_limit_seconds)) {
    fail(ErrorCode::kInvalidArgument,
         "nonlinear options: tolerance must be in (0, 1), max_iterations and max_load_steps >= 1, "
         "tangent_gauss_points 0..10, early_rule_levels -1..8, time_limit_seconds finite and >= 0");
  }
}

NonlinearSolver::~NonlinearSolver() = default;

std::shared_ptr<const internal::NonlinearShell> NonlinearSolver::shell() const {
  std::lock_guard lock(mutex_);
  if (!shell_) {
    shell_ = internal::NonlinearShell::build(model_, options_.threads, options_.tangent_gauss_points, options_.executor,
                                             options_.approximate_directions ? options_.early_rule_levels : -1);
  }
  return shell_;
}

size_t NonlinearSolver::memory_bytes() const {
  std::lock_guard lock(mutex_);
  size_t bytes = sizeof(*this) + (shell_ ? shell_->memory_bytes() : 0);
  if (memory_) {
    const internal::NonlinearMemory& m = *memory_;
    bytes += sizeof(m) + static_cast<size_t>(m.end.size() + m.end_force.size()) * sizeof(double);
    for (const auto& [targets, u] : m.history) bytes += static_cast<size_t>(targets.size() + u.size()) * sizeof(double);
    // The factor and its matrix are the last preconditioner's unless they are the linear ones,
    // which the factor cache holds (and counts) and the model holds.
    if (m.factor && !m.factor_is_k) bytes += m.factor->bytes();
    if (m.matrix && !m.factor_is_k) {
      bytes += static_cast<size_t>(m.matrix->nonZeros()) * (sizeof(double) + sizeof(int)) +
               static_cast<size_t>(m.matrix->outerSize() + 1) * sizeof(int);
    }
  }
  return bytes;
}

Result<NonlinearSolution> NonlinearSolver::solve(const DeformationRequest& request) const {
  return solve_from(request, nullptr);
}

Result<NonlinearSolution> NonlinearSolver::solve(const DeformationRequest& request, const Eigen::VectorXd& initial) const {
  return solve_from(request, &initial);
}

Result<NonlinearSolution> NonlinearSolver::solve_from(const DeformationRequest& request,
                                                      const Eigen::VectorXd* initial) const {
  try {
    auto sh = shell();
    std::shared_ptr<const internal::NonlinearMemory> memory;
    {
      std::lock_guard lock(mutex_);
      memory = memory_;
    }
    Run run(model_, *sh, *cache_, options_, request, initial, memory);
    NonlinearSolution solution = run.run();
    std::lock_guard lock(mutex_);
    memory_ = run.memory_out();
    return solution;
  } catch (const Exception& e) {
    return e.error();
  } catch (const std::bad_alloc&) {
    return Error{ErrorCode::kResourceExhausted, "out of memory in the nonlinear solve"};
  } catch (const std::exception& e) {
    return Error{ErrorCode::kInternal, std::string("internal error: ") + e.what()};
  }
}

}  // namespace softshell::engine
