// Issue 16's drag along several paths: the grab of bench_drag.h pulled in `paths` horizontal
// directions spread around the vertical axis, in `steps` steps each, with what the solver did for
// each step. Where the shell buckles under the grab (spot_quadrangulated), any change to the solver,
// even one that changes only round-off, sends a drag down another path (other iterations, other
// refactorizations, sometimes a refusal), so a change is judged on the sum over several paths,
// never on one drag (docs/benchmarks.md, "Nonlinear model"). One build repeats its paths exactly
// (NonlinearOptions::reproducible); with SOFTSHELL_BENCH_TIMED_REFRESH=1 the refresh rule reads
// the clock, and the host's load changes them.
//
// Usage: bench_drag_paths [mesh = spot_quadrangulated.obj] [paths = 4] [steps = 20] [only path k]
// Path k pulls along the drag's direction turned by k * 360 / paths degrees about the vertical (y).
// SOFTSHELL_BENCH_STEPS=1 prints every drag step; SOFTSHELL_BENCH_LOAD_STEPS=1 also every load
// step in it (NonlinearOptions::on_load_step), with the residual at each of its iterations.
// SOFTSHELL_BENCH_THICKNESS_MM sets the shell's thickness (bench_drag.h; the benchmark's is 2 mm).

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "bench_drag.h"
#include "bench_support.h"
#include "softshell/engine/nonlinear_solver.h"
#include "test_meshes.h"

using namespace softshell;

namespace {

struct PathTotals {
  int steps = 0, newton = 0, krylov = 0, factorizations = 0, load_steps = 0;
  double ms = 0.0;
  std::vector<double> step_ms;
  std::string error;

  void add(const PathTotals& t) {
    steps += t.steps;
    newton += t.newton;
    krylov += t.krylov;
    factorizations += t.factorizations;
    load_steps += t.load_steps;
    ms += t.ms;
    step_ms.insert(step_ms.end(), t.step_ms.begin(), t.step_ms.end());
  }
};

// One line per load step: where it went along its request, how it ended, what it took, and the
// exponents of its relative out-of-balance forces (-2.3 is 5e-3), iteration by iteration.
void print_load_step(const engine::NonlinearLoadStep& s) {
  std::printf("      load step %.4f -> %.4f %s: %d iterations (%d trust-region), %d Krylov, %d factors, %.0f ms; "
              "log10 residuals",
              s.from, s.to, s.converged ? "converged" : "FAILED", s.iterations, s.trust_region_steps,
              s.krylov_iterations, s.factorizations, s.ms);
  for (double r : s.residuals) {
    if (r > 0.0) {
      std::printf(" %.1f", std::log10(r));
    } else {
      std::printf(" -inf");
    }
  }
  std::printf("\n");
}

PathTotals drag_path(const bench::Drag& drag, int steps, bool verbose, bool load_steps) {
  PathTotals totals;
  engine::NonlinearOptions options = bench::drag_options();
  if (load_steps) options.on_load_step = print_load_step;
  engine::NonlinearSolver solver(drag.model, std::make_shared<engine::FactorCache>(), options);
  DeformationRequest request = drag.request;
  auto first = solver.solve(request);  // the basis and the factor of K, not timed
  if (!first.ok()) {
    totals.error = first.error().message;
    return totals;
  }
  Eigen::VectorXd u = first->displacement;
  for (int k = 1; k <= steps; ++k) {
    request.limit_constraints[0].displacement = drag.grab_at(k, steps);
    const auto t0 = bench::Clock::now();
    auto step = solver.solve(request, u);
    const double ms = bench::ms_since(t0);
    if (!step.ok()) {
      totals.error = "step " + std::to_string(k) + ": " + step.error().message;
      return totals;
    }
    const engine::NonlinearStats& s = step->stats;
    if (verbose) {
      std::printf("    step %2d: %8.1f ms, %3d Newton, %4d Krylov, %3d factors, %d load steps\n", k, ms, s.iterations,
                  s.krylov_iterations, s.factorizations, s.load_steps);
      std::fflush(stdout);
    }
    totals.add({1, s.iterations, s.krylov_iterations, s.factorizations, s.load_steps, ms, {ms}, {}});
    u = step->displacement;
  }
  return totals;
}

}  // namespace

int main(int argc, char** argv) {
  bench::malloc_as_the_server();
  const std::string name = argc > 1 ? argv[1] : "spot_quadrangulated.obj";
  const int paths = argc > 2 ? std::atoi(argv[2]) : 4;
  const int steps = argc > 3 ? std::atoi(argv[3]) : 20;
  const int only = argc > 4 ? std::atoi(argv[4]) : -1;
  if (paths < 1 || steps < 1 || only >= paths || (argc > 4 && only < 0)) {
    std::fprintf(stderr, "usage: bench_drag_paths [mesh] [paths >= 1] [steps >= 1] [only path 0..paths-1]\n");
    return 2;
  }
  auto drag = bench::setup_drag(test::load_asset_mesh(name));
  if (!drag.ok()) {
    std::fprintf(stderr, "%s: %s\n", name.c_str(), drag.error().message.c_str());
    return 1;
  }
  const bool load_steps = std::getenv("SOFTSHELL_BENCH_LOAD_STEPS") != nullptr;
  const bool verbose = load_steps || std::getenv("SOFTSHELL_BENCH_STEPS") != nullptr;
  std::printf("%s, %d DOFs, t = %g mm: the grab dragged to 30%% of the size in %d steps, %d paths (%s)\n\n",
              name.c_str(), drag->model->num_dofs(), 1e3 * bench::drag_material().thickness, steps, paths,
              bench::machine().c_str());
  std::printf("| path | direction | steps | total | step p50 | step max | Newton | Krylov | factors | load steps |\n");
  std::printf("| ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  std::fflush(stdout);
  PathTotals sum;
  for (int k = std::max(only, 0); k < (only >= 0 ? only + 1 : paths); ++k) {
    const double turn = 2.0 * M_PI * k / paths;
    bench::Drag path = *drag;
    const Vec3& d = drag->direction;
    path.direction = Vec3(std::cos(turn) * d.x() + std::sin(turn) * d.z(), 0.0, -std::sin(turn) * d.x() + std::cos(turn) * d.z());
    const PathTotals t = drag_path(path, steps, verbose, load_steps);
    char where[64];
    std::snprintf(where, sizeof where, "(%.2f, 0, %.2f)", path.direction.x(), path.direction.z());
    std::printf("| %d | %s | %d%s | %.2f s | %.0f ms | %.0f ms | %d | %d | %d | %d |\n", k, where, t.steps,
                t.error.empty() ? "" : " (refused)", 1e-3 * t.ms, bench::percentile(t.step_ms, 0.5),
                bench::percentile(t.step_ms, 1.0), t.newton, t.krylov, t.factorizations, t.load_steps);
    if (!t.error.empty()) std::printf("  path %d refused %s\n", k, t.error.c_str());
    std::fflush(stdout);
    sum.add(t);
  }
  std::printf("| all | | %d | %.2f s | %.0f ms | %.0f ms | %d | %d | %d | %d |\n", sum.steps, 1e-3 * sum.ms,
              bench::percentile(sum.step_ms, 0.5), bench::percentile(sum.step_ms, 1.0), sum.newton, sum.krylov,
              sum.factorizations, sum.load_steps);
  return 0;
}
