// Precompute, factorization and warm-solve times and memory for every shipped mesh, beside the
// paper's Table 1, and a scaling curve (DOFs vs time) up to ~100k DOFs.
//
// Setup: aluminium-like material (E = 6.9e10 Pa, nu = 0.32, t = 2 mm) on the mesh scaled to a 1 m
// bounding diagonal, the bottom 5% of the control points (lowest y; per connected part, at least
// four) fixed. The first solve factorizes K with those DOFs eliminated; every later ("warm")
// solve grabs a new random limit point (random face, sub-face and (u, v)) and moves it 1 cm along
// its normal, which reuses the cached factor (triangular solves plus a 3x3 Schur system). A grab
// that the request cannot express (e.g. a point whose control points are all fixed) is skipped
// and counted. "swept" is the mean share of the factor a warm solve's forward sweep reads (the
// grab is local).
//
// Nonlinear model (issue 16's setup): the same material and supports; a grab (limit constraint)
// at the centre of the topmost face dragged in 20 steps to 30% of the object's size, across the
// object's thinnest horizontal extent (out of the plane of a flat object); each step starts from
// the previous answer and converges to a relative out-of-balance force of 1e-8. Then the same
// grab in one request from rest.
//
// Usage: bench_engine [warm solves per mesh = 50] [largest scaling-curve DOFs = 100000, 0 = none]
//                     [supports: only the support-cost table | nonlinear [steps = 20]: only the nonlinear
//                      drag | nonlinear drag steps = 20, 0 = none]
// SOFTSHELL_BENCH_STEPS=1 prints each drag step's statistics; SOFTSHELL_BENCH_TIMED_REFRESH=1 times
// instead of counting the refresh rule (NonlinearOptions::reproducible off); SOFTSHELL_BENCH_EXACT_DIRECTIONS=1 solves
// the Newton directions on the exact tangent (NonlinearOptions::approximate_directions = false);
// SOFTSHELL_BENCH_MESH=NAME drags only that mesh. malloc is set up as softshell-server sets it
// (tune_malloc_for_solves); SOFTSHELL_BENCH_DEFAULT_MALLOC=1 leaves glibc's defaults.
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <map>
#include <random>

#include "bench_drag.h"
#include "bench_support.h"
#include "shell_benchmarks.h"
#include "softshell/engine/nonlinear_solver.h"
#include "softshell/engine/solver.h"
#include "softshell/interaction.h"
#include "softshell/level_of_detail.h"
#include "softshell/limit_evaluator.h"
#include "softshell/tessellation.h"
#include "test_meshes.h"

using namespace softshell;

namespace {

using bench::kMaterial;

int count_extraordinary_vertices(const ControlMesh& mesh) {
  std::vector<int> valence(static_cast<size_t>(mesh.num_vertices()), 0);
  std::map<std::pair<int, int>, int> edges;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    auto fv = mesh.face(f);
    for (size_t i = 0; i < fv.size(); ++i) {
      const int a = fv[i], b = fv[(i + 1) % fv.size()];
      ++edges[{std::min(a, b), std::max(a, b)}];
    }
  }
  std::vector<char> boundary(valence.size(), 0);
  for (const auto& [e, n] : edges) {
    ++valence[static_cast<size_t>(e.first)];
    ++valence[static_cast<size_t>(e.second)];
    if (n == 1) boundary[static_cast<size_t>(e.first)] = boundary[static_cast<size_t>(e.second)] = 1;
  }
  int evs = 0;
  for (size_t v = 0; v < valence.size(); ++v) evs += !boundary[v] && valence[v] != 4;
  return evs;
}

struct Measurement {
  int dofs = 0;
  double precompute_ms = 0.0;
  double factor_solve_ms = 0.0;  // the first solve: factorization + solve
  double warm_p50_ms = 0.0, warm_p95_ms = 0.0;
  double stiffness_mib = 0.0, factor_mib = 0.0;
  double forward_share = 0.0;  // mean share of the factor a warm solve's forward sweep read
  int skipped = 0;
  std::string error;
};

Measurement measure(ControlMesh mesh, int warm_solves, const LimitEvaluator::Options& evaluator = {}) {
  Measurement result;
  result.dofs = 3 * mesh.num_vertices();
  const double scale = 1.0 / mesh.bounding_diagonal();
  for (Vec3& p : mesh.positions()) p *= scale;

  engine::PrecomputeOptions options;
  options.evaluator = evaluator;
  auto t0 = bench::Clock::now();
  auto model = engine::ShellModel::build(mesh, kMaterial, options);
  result.precompute_ms = bench::ms_since(t0);
  if (!model.ok()) {
    result.error = model.error().message;
    return result;
  }
  result.stiffness_mib = static_cast<double>((*model)->memory_bytes()) / (1024.0 * 1024.0);

  DeformationRequest base;
  base.vertex_constraints = test::bottom_supports(mesh, (*model)->component_of());
  auto cache = std::make_shared<engine::FactorCache>();
  engine::Solver solver(*model, cache);
  t0 = bench::Clock::now();
  auto first = solver.solve(base);
  result.factor_solve_ms = bench::ms_since(t0);
  if (!first.ok()) {
    result.error = first.error().message;
    return result;
  }
  result.factor_mib = static_cast<double>(cache->stats().bytes) / (1024.0 * 1024.0);

  const LimitEvaluator& limit = (*model)->evaluator();
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<double> times;
  for (int attempt = 0; static_cast<int>(times.size()) < warm_solves && attempt < 4 * warm_solves; ++attempt) {
    SurfacePoint point;
    point.face = static_cast<int32_t>(rng() % static_cast<unsigned>(mesh.num_faces()));
    const auto corners = static_cast<unsigned>(mesh.face(point.face).size());
    point.subface = corners == 4 ? 0 : static_cast<int32_t>(rng() % corners);
    point.u = unit(rng);
    point.v = unit(rng);
    if (!limit.check(point).ok()) {  // a ghost face of an open boundary
      ++result.skipped;
      continue;
    }
    DeformationRequest request = base;
    request.limit_constraints.push_back({point, 0.01 * limit.evaluate(point).normal(), {}, {}});
    t0 = bench::Clock::now();
    auto solution = solver.solve(request);
    const double ms = bench::ms_since(t0);
    if (!solution.ok() || solution->stats.factor_ms > 0.0) {
      ++result.skipped;  // a grab the supports make impossible (or a new factor: not a warm solve)
      continue;
    }
    times.push_back(ms);
    result.forward_share += solution->stats.forward_fraction;
  }
  if (!times.empty()) result.forward_share /= static_cast<double>(times.size());
  result.warm_p50_ms = bench::percentile(times, 0.5);
  result.warm_p95_ms = bench::percentile(times, 0.95);
  return result;
}

double cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return 1e3 * static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_nsec);
}

struct DragMeasurement {
  int dofs = 0, points = 0, steps = 0;
  double first_ms = 0.0;                  // first nonlinear solve: basis evaluation, K factor
  double step_p50_ms = 0.0, step_p95_ms = 0.0;
  double step_cpu_p50_ms = 0.0;  // process CPU time (both threads): the work, whatever the load
  double iterations = 0.0, krylov = 0.0, factorizations = 0.0;  // per step, mean
  double evaluate_share = 0.0, krylov_share = 0.0, tangent_share = 0.0;
  double worst_residual = 0.0;
  double one_shot_ms = 0.0;
  int one_shot_iterations = 0, one_shot_load_steps = 0;
  double one_shot_difference = 0.0;       // relative to the dragged answer
  double linear_off = 0.0;                // |u_linear - u_nonlinear| / |u_nonlinear| at the end
  std::string error;
};

DragMeasurement measure_drag(ControlMesh mesh, int steps) {
  DragMeasurement result;
  result.dofs = 3 * mesh.num_vertices();
  result.steps = steps;
  auto drag = bench::setup_drag(std::move(mesh));
  if (!drag.ok()) {
    result.error = drag.error().message;
    return result;
  }
  const auto& model = drag->model;
  result.points = static_cast<int>(model->quadrature().size());
  auto cache = std::make_shared<engine::FactorCache>();
  engine::NonlinearSolver solver(model, cache, bench::drag_options());
  DeformationRequest request = drag->request;
  auto t0 = bench::Clock::now();
  auto first = solver.solve(request);
  result.first_ms = bench::ms_since(t0);
  if (!first.ok()) {
    result.error = first.error().message;
    return result;
  }
  Eigen::VectorXd u = first->displacement;
  std::vector<double> times, cpu_times;
  double evaluate = 0.0, krylov = 0.0, tangent = 0.0, total = 0.0;
  for (int k = 1; k <= steps; ++k) {
    request.limit_constraints[0].displacement = drag->grab_at(k, steps);
    t0 = bench::Clock::now();
    const double cpu0 = cpu_ms();
    const long faults0 = bench::minor_faults();
    auto step = solver.solve(request, u);
    const double ms = bench::ms_since(t0);
    const long faults = bench::minor_faults() - faults0;
    cpu_times.push_back(cpu_ms() - cpu0);
    if (!step.ok()) {
      result.error = "step " + std::to_string(k) + ": " + step.error().message;
      return result;
    }
    times.push_back(ms);
    const engine::NonlinearStats& s = step->stats;
    if (std::getenv("SOFTSHELL_BENCH_STEPS")) {
      static const char* const kPrediction[] = {"none", "used", "discarded", "used after all"};
      std::printf("  step %d: %.1f ms, %d Newton (%d approximate, %d by differences, %d evaluations, %d early), %d Krylov, %d factors; "
                  "forces %.1f ms, Krylov %.1f ms, tangents %.1f ms; %ld pages faulted in; prediction %s\n", k, ms, s.iterations,
                  s.approximate_iterations, s.difference_iterations, s.evaluations, s.early_evaluations, s.krylov_iterations,
                  s.factorizations, s.evaluate_ms, s.krylov_ms, s.tangent_ms, faults,
                  kPrediction[static_cast<int>(s.prediction)]);
      std::fflush(stdout);  // a long drag shows its progress, also into a file
    }
    result.iterations += s.iterations;
    result.krylov += s.krylov_iterations;
    result.factorizations += s.factorizations;
    result.worst_residual = std::max(result.worst_residual, s.residual);
    evaluate += s.evaluate_ms;
    krylov += s.krylov_ms;
    tangent += s.tangent_ms;
    total += s.solve_ms;
    u = step->displacement;
  }
  result.iterations /= steps;
  result.krylov /= steps;
  result.factorizations /= steps;
  result.evaluate_share = evaluate / total;
  result.krylov_share = krylov / total;
  result.tangent_share = tangent / total;
  result.step_p50_ms = bench::percentile(times, 0.5);
  result.step_p95_ms = bench::percentile(times, 0.95);
  result.step_cpu_p50_ms = bench::percentile(cpu_times, 0.5);
  // The same grab from rest in one request (the basis and the factor of K are the model's, cached
  // by the first solve; a solve from rest uses neither the drag's tangent nor its history).
  t0 = bench::Clock::now();
  const long one_faults0 = bench::minor_faults();
  auto one = solver.solve(request);
  result.one_shot_ms = bench::ms_since(t0);
  const long one_faults = bench::minor_faults() - one_faults0;
  if (!one.ok()) {
    result.error = "one request: " + one.error().message;
    return result;
  }
  if (std::getenv("SOFTSHELL_BENCH_STEPS")) {
    const engine::NonlinearStats& s = one->stats;
    std::printf("  from rest: %.1f ms, %d load steps, %d Newton (%d approximate, %d by differences, %d evaluations, %d early), "
                "%d Krylov, %d factors; forces %.1f ms, Krylov %.1f ms, tangents %.1f ms; %ld pages faulted in\n",
                result.one_shot_ms, s.load_steps, s.iterations, s.approximate_iterations, s.difference_iterations,
                s.evaluations, s.early_evaluations, s.krylov_iterations, s.factorizations, s.evaluate_ms, s.krylov_ms, s.tangent_ms,
                one_faults);
  }
  result.one_shot_iterations = one->stats.iterations;
  result.one_shot_load_steps = one->stats.load_steps;
  result.one_shot_difference = (one->displacement - u).norm() / u.norm();
  auto linear = engine::Solver(model, cache).solve(request);
  if (linear.ok()) result.linear_off = (linear->displacement - u).norm() / u.norm();
  return result;
}

// Warm-solve cost of two kinds of supports with a new random grab per request (issue 12,
// "Constraints at full speed"): the same mesh, material and grabs, the object held either by the
// lowest 5% of the control points (vertex supports: eliminated in the factor) or by a floor of
// limit constraints, one per touching face, as the SDK's floor_contact builds them (level-3
// tessellation, the lowest 1% of the size touching, more until the floor holds every rigid
// motion, as the demo does). Each grab is solved with both supports one after the other (in
// alternating order), so that load on the machine affects both alike.
struct SupportCost {
  int rows = 0;           // constraint rows of the supports
  double first_ms = 0.0;  // first solve (the factorization)
  double second_ms = 0.0; // second solve (for the floor: its rows are cached)
  std::vector<double> times;
  int skipped = 0;
};

void support_costs(ControlMesh mesh, int warm_solves, SupportCost& vertex, SupportCost& floor) {
  const double scale = 1.0 / mesh.bounding_diagonal();
  for (Vec3& p : mesh.positions()) p *= scale;
  auto model = engine::ShellModel::build(mesh, kMaterial).value();
  DeformationRequest on_vertices, on_floor;
  on_vertices.vertex_constraints = test::bottom_supports(mesh, model->component_of());
  {
    const Tessellation surface = Tessellation::create(model->evaluator(), 3).value();
    double floor_y = std::numeric_limits<double>::infinity();
    for (const Vec3& p : surface.vertices()) floor_y = std::min(floor_y, p.y());
    FloorContact contact;
    for (double tolerance : {0.01, 0.03, 0.06, 0.12}) {
      contact = floor_contact(surface, Plane{Vec3(0.0, floor_y, 0.0), Vec3::UnitY()}, {tolerance}).value();
      if (contact.fixes_rigid_motion) break;
    }
    contact.add_to(on_floor);
    floor.rows = static_cast<int>(3 * contact.limit_constraints.size());
  }
  engine::Solver solver(model, std::make_shared<engine::FactorCache>());
  const LimitEvaluator& limit = model->evaluator();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int solve = 0, attempt = 0; solve < warm_solves + 2 && attempt < 4 * (warm_solves + 2); ++attempt) {
    SurfacePoint point;
    point.face = static_cast<int32_t>(rng() % static_cast<unsigned>(mesh.num_faces()));
    const auto corners = static_cast<unsigned>(mesh.face(point.face).size());
    point.subface = corners == 4 ? 0 : static_cast<int32_t>(rng() % corners);
    point.u = unit(rng);
    point.v = unit(rng);
    if (!limit.check(point).ok()) continue;
    const LimitConstraint grab{point, 0.01 * limit.evaluate(point).normal(), {}, {}};
    double ms[2] = {0.0, 0.0};
    bool ok[2] = {false, false};
    for (int k = 0; k < 2; ++k) {
      const int which = (solve + k) % 2;  // alternate which support goes first
      DeformationRequest request = which == 0 ? on_vertices : on_floor;
      request.limit_constraints.push_back(grab);
      const auto t0 = bench::Clock::now();
      ok[which] = solver.solve(request).ok();
      ms[which] = bench::ms_since(t0);
    }
    if (!ok[0] || !ok[1]) {  // a grab the vertex supports hold entirely (all its control points fixed)
      ++vertex.skipped;
      continue;
    }
    for (int which = 0; which < 2; ++which) {
      SupportCost& cost = which == 0 ? vertex : floor;
      if (solve == 0) {
        cost.first_ms = ms[which];
      } else if (solve == 1) {
        cost.second_ms = ms[which];
      } else {
        cost.times.push_back(ms[which]);
      }
    }
    ++solve;
  }
}

const char* paper_row(int control_points) {
  return control_points < 135   ? "Cactus (60 CVs): 14 s / 2 ms"
         : control_points < 345 ? "Barrel (210) / Car door (218): 7 s, 20 s / 18 ms"
                                : "Horse (472 CVs): 82 s / 75 ms";
}

}  // namespace

int main(int argc, char** argv) {
  bench::malloc_as_the_server();
  const int warm_solves = argc > 1 ? std::max(1, std::atoi(argv[1])) : 50;
  const int max_scaling_dofs = argc > 2 ? std::atoi(argv[2]) : 100'000;
  const bool supports_only = argc > 3 && std::string(argv[3]) == "supports";
  const bool nonlinear_only = argc > 3 && std::string(argv[3]) == "nonlinear";
  const int drag_steps = supports_only ? 0 : nonlinear_only ? (argc > 4 ? std::atoi(argv[4]) : 20)
                                                            : argc > 3 ? std::atoi(argv[3]) : 20;
  std::printf("softshell engine benchmark on %s\n", bench::machine().c_str());
  std::printf("E = 6.9e10 Pa, nu = 0.32, t = 2 mm, mesh scaled to a 1 m diagonal, lowest 5%% of the control "
              "points (per part, at least 4) fixed; warm solve = a new random limit constraint on the cached factor (%d per mesh)\n",
              warm_solves);
  std::printf("paper (Table 1, Intel i7-3820, precompute / solve): Cactus 60 CVs 14 s / 2 ms, Barrel 210 CVs "
              "7 s / 18 ms, Car door 218 CVs 20 s / 18 ms, Horse 472 CVs 82 s / 75 ms\n\n");
  std::printf("| mesh | CVs | EVs | DOFs | precompute | first solve (factor) | warm solve p50 | p95 | swept | K | "
              "factor | paper, nearest size |\n");
  std::printf("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |\n");
  std::string skipped;
  for (const std::string& name : test::asset_mesh_names()) {
    if (supports_only || nonlinear_only) break;
    const ControlMesh mesh = test::load_asset_mesh(name);
    const Measurement m = measure(mesh, warm_solves);
    if (!m.error.empty()) {
      std::printf("| %s | %d | | %d | %s |\n", name.c_str(), mesh.num_vertices(), m.dofs, m.error.c_str());
      continue;
    }
    std::printf("| %s | %d | %d | %d | %.0f ms | %.1f ms | %.2f ms | %.2f ms | %.0f%% | %.1f MiB | %.1f MiB | %s |\n",
                name.c_str(), mesh.num_vertices(), count_extraordinary_vertices(mesh), m.dofs, m.precompute_ms,
                m.factor_solve_ms, m.warm_p50_ms, m.warm_p95_ms, 100.0 * m.forward_share, m.stiffness_mib, m.factor_mib,
                paper_row(mesh.num_vertices()));
    if (m.skipped) skipped += " " + name + ": " + std::to_string(m.skipped);
    std::fflush(stdout);
  }
  if (!skipped.empty()) std::printf("\ngrabs skipped (on a ghost face, or held entirely by the supports):%s\n", skipped.c_str());

  if (drag_steps > 0) {
    std::printf("\nNonlinear model: a grab dragged in %d steps to 30%% of the size, each step converged to 1e-8, "
                "t = %g mm (targets, at 2 mm: catmark_righthanded p50 <= 30 ms per step and <= 300 ms in one request; "
                "spot_quadrangulated p50 <= 150 ms per step)\n\n", drag_steps, 1e3 * bench::drag_material().thickness);
    std::printf("| mesh | DOFs | quadrature points | first solve (basis) | step p50 | p95 | CPU p50 | Newton / Krylov / "
                "factors per step | time in forces / Krylov / tangents | worst residual | one request from rest | linear "
                "model off by |\n");
    std::printf("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
    const char* only = std::getenv("SOFTSHELL_BENCH_MESH");
    for (const char* name : {"catmark_righthanded.obj", "spot_quadrangulated.obj"}) {
      if (only && std::string(only) != name) continue;
      const DragMeasurement d = measure_drag(test::load_asset_mesh(name), drag_steps);
      if (!d.error.empty()) {
        std::printf("| %s | %d | %d | %s |\n", name, d.dofs, d.points, d.error.c_str());
        continue;
      }
      std::printf("| %s | %d | %d | %.0f ms | %.0f ms | %.0f ms | %.0f ms | %.1f / %.1f / %.1f | %.0f%% / %.0f%% / %.0f%% | "
                  "%.1e | %.0f ms (%d iterations, %d load steps; differs by %.0e) | %.0f%% |\n",
                  name, d.dofs, d.points, d.first_ms, d.step_p50_ms, d.step_p95_ms, d.step_cpu_p50_ms, d.iterations, d.krylov,
                  d.factorizations, 100 * d.evaluate_share, 100 * d.krylov_share, 100 * d.tangent_share,
                  d.worst_residual, d.one_shot_ms, d.one_shot_iterations, d.one_shot_load_steps, d.one_shot_difference,
                  100 * d.linear_off);
      std::fflush(stdout);
    }
  }

  if (nonlinear_only) return 0;
  std::printf("\nSupports + a new random grab per request (same setup; floor = sdk floor_contact's limit points; "
              "both supports solved for each grab, interleaved; %d warm solves)\n\n", warm_solves);
  std::printf("| mesh | supports | rows | first solve | second solve | warm p50 | p95 | warm p50 / vertex supports |\n");
  std::printf("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  for (const char* name : {"spot_quadrangulated.obj", "blub_quadrangulated.obj"}) {
    SupportCost vertex, floor;
    support_costs(test::load_asset_mesh(name), warm_solves, vertex, floor);
    const double base = bench::percentile(vertex.times, 0.5);
    for (const auto& [label, cost] : {std::pair{"lowest 5% vertex supports", &vertex}, std::pair{"floor (limit points)", &floor}}) {
      const double p50 = bench::percentile(cost->times, 0.5);
      std::printf("| %s | %s | %d | %.1f ms | %.1f ms | %.2f ms | %.2f ms | %.2f |\n", name, label, cost->rows,
                  cost->first_ms, cost->second_ms, p50, bench::percentile(cost->times, 0.95), base > 0.0 ? p50 / base : 0.0);
    }
    std::fflush(stdout);
  }
  if (max_scaling_dofs <= 0) return 0;

  // Scaling: a cylindrical roof (curved, so membrane and bending couple) at growing resolution,
  // and a real mesh (spot_quadrangulated) refined with OpenSubdiv.
  std::printf("\nScaling (same setup)\n\n");
  std::printf("| mesh | DOFs | precompute | first solve (factor) | warm solve p50 | p95 | swept | K | factor |\n");
  std::printf("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  auto row = [](const std::string& label, const Measurement& m) {
    if (!m.error.empty()) {
      std::printf("| %s | %d | %s |\n", label.c_str(), m.dofs, m.error.c_str());
    } else {
      std::printf("| %s | %d | %.0f ms | %.0f ms | %.2f ms | %.2f ms | %.0f%% | %.1f MiB | %.1f MiB |\n", label.c_str(),
                  m.dofs, m.precompute_ms, m.factor_solve_ms, m.warm_p50_ms, m.warm_p95_ms, 100.0 * m.forward_share,
                  m.stiffness_mib, m.factor_mib);
    }
    std::fflush(stdout);
  };
  const int scaling_solves = std::min(warm_solves, 20);
  for (int n : {8, 16, 32, 64, 96, 128, 160, 181}) {
    if (3 * (n + 1) * (n + 1) > max_scaling_dofs) break;
    const ControlMesh roof = test::make_grid(n, n, 1.0, 1.0, [](double x, double) { return 0.3 * std::sin(M_PI * x); });
    row("roof " + std::to_string(n) + "x" + std::to_string(n), measure(roof, scaling_solves));
  }
  const ControlMesh spot = test::load_asset_mesh("spot_quadrangulated.obj");
  row("spot_quadrangulated", measure(spot, scaling_solves));
  for (int levels = 1; levels <= 2; ++levels) {
    auto refined = MeshRefinement::create(spot, levels);
    if (!refined.ok() || 3 * refined->fine().num_vertices() > max_scaling_dofs) break;
    row("spot_quadrangulated, refined x" + std::to_string(levels),
        measure(refined->fine(), scaling_solves, refined->fine_evaluator_options({})));
  }
  return 0;
}
