// The cost of each pass of the nonlinear model over its quadrature points, timed in one process:
// the passes a drag step is made of (docs/benchmarks.md, "Nonlinear model"). Whole drag steps vary
// 10-20% with the host's load and follow the solver's path; a pass is a fixed amount of work, so
// a change to the kernels is judged here, interleaved with the build before it.
//
// bench_engine's drag (bench_drag.h); the state is the answer after `bent` of its 20 steps, so the
// frames and stresses are those of a bent shell.
//
// Usage: bench_nonlinear_passes [mesh = catmark_righthanded.obj] [rounds = 3] [bent = 10]
// Each round prints the median and 90th percentile of every pass, on all threads, then on one.

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "bench_drag.h"
#include "bench_support.h"
#include "nonlinear_shell.h"
#include "softshell/engine/nonlinear_solver.h"
#include "test_meshes.h"

using namespace softshell;

namespace {

struct Timing {
  double p50 = 0.0, p90 = 0.0;
};

template <class Pass>
Timing time_pass(int repeats, Pass pass) {
  std::vector<double> ms;
  for (int i = 0; i < repeats; ++i) {
    const auto t0 = bench::Clock::now();
    pass();
    ms.push_back(bench::ms_since(t0));
  }
  return {bench::percentile(ms, 0.5), bench::percentile(ms, 0.9)};
}

}  // namespace

int main(int argc, char** argv) {
  bench::malloc_as_the_server();
  const std::string name = argc > 1 ? argv[1] : "catmark_righthanded.obj";
  const int rounds = argc > 2 ? std::atoi(argv[2]) : 3;
  const int bent = argc > 3 ? std::atoi(argv[3]) : 10;
  if (rounds < 1 || bent < 0 || bent > 20) {
    std::fprintf(stderr, "usage: bench_nonlinear_passes [mesh] [rounds >= 1] [bent steps 0..20]\n");
    return 2;
  }
  auto drag = bench::setup_drag(test::load_asset_mesh(name));
  if (!drag.ok()) {
    std::fprintf(stderr, "%s: %s\n", name.c_str(), drag.error().message.c_str());
    return 1;
  }
  const auto& model = drag->model;

  // The drag's state after `bent` steps.
  engine::NonlinearSolver solver(model, std::make_shared<engine::FactorCache>(), {});
  DeformationRequest request = drag->request;
  Eigen::VectorXd u = Eigen::VectorXd::Zero(model->num_dofs());
  for (int k = 1; k <= bent; ++k) {
    request.limit_constraints[0].displacement = drag->grab_at(k, 20);
    auto step = solver.solve(request, u);
    if (!step.ok()) {
      std::fprintf(stderr, "drag step %d: %s\n", k, step.error().message.c_str());
      return 1;
    }
    u = step->displacement;
  }

  // The solver's configuration (the coarse rule with its Gauss points per (sub-)face), on all the
  // executor's threads and on one.
  const engine::NonlinearOptions defaults;
  struct Passes {
    int threads;
    std::shared_ptr<const engine::internal::NonlinearShell> shell;
    engine::internal::ShellState state, coarse, early;
  };
  std::vector<Passes> configurations;
  for (int threads : {0, 1}) {
    Passes c{threads,
             engine::internal::NonlinearShell::build(model, threads, defaults.tangent_gauss_points, nullptr,
                                                     defaults.early_rule_levels),
             {}, {}, {}};
    if (!c.shell->evaluate(u, c.state, false, true) || !c.shell->evaluate_coarse(u, c.coarse)) {
      std::fprintf(stderr, "the bent state is degenerate\n");
      return 1;
    }
    configurations.push_back(std::move(c));
  }
  const Eigen::VectorXd v = Eigen::VectorXd::Random(u.size());
  Eigen::VectorXd out(u.size());
  const Eigen::MatrixXd vm = v;
  Eigen::MatrixXd om;
  Eigen::SparseMatrix<double> matrix;

  std::printf("softshell nonlinear passes on %s\n", bench::machine().c_str());
  std::printf("%s: %d DOFs, %zu points in the model's rule; the drag's state after %d of 20 steps\n\n", name.c_str(),
              model->num_dofs(), configurations[0].shell->num_points(), bent);
  std::printf("| round | threads | evaluate | evaluate + point data | exact tangent product | coarse evaluate | "
              "approximate product | approximate assembly | early evaluate |\n");
  std::printf("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  auto cell = [](const Timing& t) {
    char text[64];
    std::snprintf(text, sizeof text, "%.2f (%.2f) ms", t.p50, t.p90);
    return std::string(text);
  };
  for (int round = 1; round <= rounds; ++round) {
    for (Passes& c : configurations) {
      const auto& shell = *c.shell;
      const Timing e = time_pass(30, [&] { shell.evaluate(u, c.state, false, false); });
      const Timing ep = time_pass(30, [&] { shell.evaluate(u, c.state, false, true); });
      const Timing tp = time_pass(30, [&] { shell.tangent_product(c.state, 0.0, vm, om); });
      const Timing ec = time_pass(100, [&] { shell.evaluate_coarse(u, c.coarse); });
      const Timing ap = time_pass(100, [&] { shell.approximate_tangent_product(c.coarse, 0.0, v, out); });
      const Timing as = time_pass(20, [&] { shell.assemble_approximate_tangent(c.coarse, 0.0, matrix); });
      const Timing ee = time_pass(30, [&] { shell.evaluate_early(u, c.early, false); });
      std::printf("| %d | %s | %s | %s | %s | %s | %s | %s | %s |\n", round, c.threads == 0 ? "all" : "1",
                  cell(e).c_str(), cell(ep).c_str(), cell(tp).c_str(), cell(ec).c_str(), cell(ap).c_str(),
                  cell(as).c_str(), cell(ee).c_str());
    }
  }
  std::printf("\nmedian (90th percentile) of 30 passes (100 for the coarse rule's, 20 assemblies) each\n");
  return 0;
}
