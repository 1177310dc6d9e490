// The nonlinear model against the point-loaded benchmarks of Sze, Liu and Lo 2004, "Popular
// benchmark problems for geometric nonlinear analysis of shells" (Finite Elements in Analysis and
// Design 40, 1551-1569): the pulled-out open cylinder and the hemisphere with an 18 degree hole.
// Symmetric parts of the shells (mirror planes as constraints, tests/support/shell_benchmarks.h),
// loaded in the paper's steps, each solve starting from the previous answer. Each test prints
// its table beside the paper's; the finer meshes are in tests/bench/bench_nonlinear_reference.cpp.
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include <gtest/gtest.h>

#include "shell_benchmarks.h"
#include "softshell/engine/nonlinear_solver.h"

namespace softshell::engine {
namespace {

Vec3 limit_displacement(const ShellModel& model, const Eigen::VectorXd& u, const SurfacePoint& p) {
  LimitStencil st = model.evaluator().stencil(p);
  Vec3 d = Vec3::Zero();
  for (size_t k = 0; k < st.size(); ++k) d += st.position[k] * u.segment<3>(3 * st.indices[k]);
  return d;
}

template <class Benchmark, class Measure>
double run(const char* name, const Benchmark& bench, const test::SzeRow* rows, size_t n, int columns, Measure measure) {
  auto model = ShellModel::build(bench.grid.mesh, Benchmark::material()).value();
  NonlinearSolver solver(model, std::make_shared<FactorCache>());
  Eigen::VectorXd u = Eigen::VectorXd::Zero(model->num_dofs());
  double worst = 0.0;
  for (size_t k = 0; k < n; ++k) {
    const test::SzeRow& row = rows[k];
    auto solution = solver.solve(bench.request(row.load_fraction * Benchmark::kMaxLoad), u);
    if (!solution.ok()) {
      std::printf("%s %dx%d P/Pmax %.3f: %s\n", name, bench.grid.nu, bench.grid.nv, row.load_fraction,
                  solution.error().message.c_str());
      return -1;
    }
    u = solution->displacement;
    const Vec3 m = measure(*model, u);
    const double ref[3] = {row.first, row.second, row.third};
    std::printf("%s %2dx%-2d %6.3f", name, bench.grid.nu, bench.grid.nv, row.load_fraction);
    for (int c = 0; c < columns; ++c) {
      std::printf("  %7.3f %7.3f %7.2f%%", m[c], ref[c], 100 * (m[c] / ref[c] - 1));
      worst = std::max(worst, std::abs(m[c] / ref[c] - 1));
    }
    std::printf("  %4d it %3d steps %.0f ms\n", solution->stats.iterations, solution->stats.load_steps,
                solution->stats.solve_ms);
  }
  return worst;
}

TEST(NonlinearBenchmarks, PulledOutCylinder) {
  const int nt = std::getenv("NT") ? std::atoi(std::getenv("NT")) : 12;
  const int nl = std::getenv("NL") ? std::atoi(std::getenv("NL")) : 8;
  const test::PulloutCylinder c = test::make_pullout_cylinder(nt, nl);
  run("cyl", c, test::kSzePulloutCylinder, std::size(test::kSzePulloutCylinder), 3,
      [&](const ShellModel& m, const Eigen::VectorXd& u) {
        return Vec3(limit_displacement(m, u, c.a()).z(), -limit_displacement(m, u, c.b()).x(),
                    -limit_displacement(m, u, c.c()).x());
      });
}

TEST(NonlinearBenchmarks, Hemisphere) {
  const int n = std::getenv("NH") ? std::atoi(std::getenv("NH")) : 8;
  const test::OpenHemisphere h = test::make_open_hemisphere(n, n);
  run("hemi", h, test::kSzeHemisphere, std::size(test::kSzeHemisphere), 2,
      [&](const ShellModel& m, const Eigen::VectorXd& u) {
        return Vec3(limit_displacement(m, u, h.a()).x(), -limit_displacement(m, u, h.b()).y(), 0.0);
      });
}

}  // namespace
}  // namespace softshell::engine
