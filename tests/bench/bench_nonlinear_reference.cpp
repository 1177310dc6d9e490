// Accuracy of the nonlinear model against reference solutions, at two or three mesh levels: the
// tables of docs/accuracy.md, "The nonlinear model: accuracy against reference solutions". The
// tests (tests/engine/nonlinear_*_test.cpp) assert the coarser levels; this program adds the finer
// ones. Run: build/tests/bench/bench_nonlinear_reference [--quick] (--quick: the tests' levels).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "bench_support.h"
#include "limit_displacement.h"
#include "shell_benchmarks.h"
#include "softshell/engine/nonlinear_solver.h"
#include "softshell/engine/solver.h"
#include "test_meshes.h"

namespace softshell::engine {
namespace {

using test::limit_displacement;

// The clamp of a ghost-layer strip at x = 0: position and both tangents held at the ends and the
// middle of every face edge (the trace is a cubic spline, so this holds it exactly).
void clamp_left_edge(const test::Plate& strip, DeformationRequest& request) {
  for (int j = 0; j < strip.ny; ++j) {
    for (double t : {0.0, 0.5, 1.0}) {
      request.limit_constraints.push_back({strip.at(0.0, (j + t) / strip.ny), Vec3::Zero(), Vec3::Zero(), Vec3::Zero()});
    }
  }
}

// Mattiasson (1981), the elastica under a dead tip load: tip deflection / L, vertical and
// horizontal, for P L^2 / EI = 1, 2, 5, 10 (the values of issue 16 and of
// tests/engine/nonlinear_reference_test.cpp).
void cantilever_against_the_elastica(const std::vector<int>& levels) {
  constexpr double kLength = 1.0, kWidth = 0.1, kThickness = 0.01, kYoung = 1.0e7;
  const double ei = kYoung * kWidth * kThickness * kThickness * kThickness / 12.0;
  const auto& reference = test::kMattiassonCantilever;
  std::printf("\n### Cantilever under a dead tip load (nu = 0, ghost-layer clamp): tip deflection / L against "
              "the elastica (Mattiasson 1981)\n\n");
  std::printf("| faces | PL²/EI | -w/L | reference | difference | -u/L | reference | difference | iterations |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|\n");
  for (int nx : levels) {
    const test::Plate strip = test::make_rectangle(nx, 2, kLength, kWidth, true);
    auto model = ShellModel::build(strip.mesh, Material{kYoung, 0.0, kThickness, 0.0}).value();
    NonlinearSolver solver(model, std::make_shared<FactorCache>());
    DeformationRequest request;
    clamp_left_edge(strip, request);
    const double g = 0.5 / std::sqrt(3.0);  // 2-point Gauss per face edge: the line load exactly
    std::vector<SurfacePoint> points;
    for (int j = 0; j < strip.ny; ++j) {
      for (double t : {0.5 - g, 0.5 + g}) points.push_back(strip.at(1.0, (j + t) / strip.ny));
    }
    for (const test::ElasticaPoint& ref : reference) {
      request.surface_forces.clear();
      const double p = ref.load * ei / (kLength * kLength) / static_cast<double>(points.size());
      for (const SurfacePoint& point : points) request.surface_forces.push_back({point, Vec3(0.0, 0.0, -p)});
      auto solution = solver.solve(request);
      if (!solution.ok()) {
        std::printf("| %dx2 | %.0f | refused: %s |\n", nx, ref.load, solution.error().message.c_str());
        continue;
      }
      const Vec3 tip = limit_displacement(*model, solution->displacement, strip.at(1.0, 0.5));
      const double v = -tip.z() / kLength, h = -tip.x() / kLength;
      std::printf("| %dx2 | %.0f | %.5f | %.5f | %+.3f%% | %.5f | %.5f | %+.3f%% | %d |\n", nx, ref.load, v, ref.vertical,
                  100 * (v / ref.vertical - 1), h, ref.horizontal, 100 * (h / ref.horizontal - 1),
                  solution->stats.iterations);
    }
  }
}

// The strip rolled up by an end rotation (Sze, Liu and Lo 2004, the cantilever under an end
// moment: L = 12, b = 1, t = 0.1, E = 1.2e6, nu = 0): the circle, tip at
// (L sin(theta) / theta, -L (1 - cos(theta)) / theta); see nonlinear_reference_test.cpp for why the
// rotation is prescribed and the energy is compared with EI theta^2 / (2 L) (1 - delta).
void end_moment(const std::vector<int>& levels) {
  constexpr double kLength = 12.0, kWidth = 1.0, kThickness = 0.1, kYoung = 1.2e6;
  const double ei = kYoung * kWidth * kThickness * kThickness * kThickness / 12.0;
  std::printf("\n### Cantilever rolled up by an end rotation (Sze, Liu, Lo 2004): tip against the exact circle\n\n");
  std::printf("| faces | turn | -u/L | exact | -w/L | exact | tip error / L | energy - exact | -delta |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|\n");
  for (int nx : levels) {
    const test::Plate strip = test::make_rectangle(nx, 2, kLength, kWidth, true);
    auto model = ShellModel::build(strip.mesh, Material{kYoung, 0.0, kThickness, 0.0}).value();
    NonlinearSolver solver(model, std::make_shared<FactorCache>());
    DeformationRequest request;
    clamp_left_edge(strip, request);
    std::vector<SurfacePoint> tip_points;
    for (int j = 0; j < strip.ny; ++j) {
      for (double t : {0.0, 0.5, 1.0}) {
        if (j == 0 || t > 0.0) tip_points.push_back(strip.at(1.0, (j + t) / strip.ny));
      }
    }
    Eigen::VectorXd u = Eigen::VectorXd::Zero(model->num_dofs());
    for (int degrees = 15; degrees <= 360; degrees += 15) {
      const double theta = degrees * M_PI / 180.0;
      const Eigen::Matrix3d turn = Eigen::AngleAxisd(theta, Vec3::UnitY()).toRotationMatrix();
      request.lagrange_constraints = test::turned_tangents(model->evaluator(), tip_points, turn);
      auto solution = solver.solve(request, u);
      if (!solution.ok()) {
        std::printf("| %dx2 | %d° | refused: %s |\n", nx, degrees, solution.error().message.c_str());
        break;
      }
      u = solution->displacement;
      if (degrees % 90 != 0) continue;
      const Vec3 tip = limit_displacement(*model, u, strip.at(1.0, 0.5)) / kLength;
      const Vec3 exact(std::sin(theta) / theta - 1.0, 0.0, -(1.0 - std::cos(theta)) / theta);
      const double energy = solution->stats.strain_energy / (ei * theta * theta / (2.0 * kLength)) - 1.0;
      const double delta = std::pow(kThickness * theta / kLength, 2) / 12.0;
      std::printf("| %dx2 | %d° | %.5f | %.5f | %.5f | %.5f | %.1e | %+.4f%% | %+.4f%% |\n", nx, degrees, -tip.x(),
                  -exact.x(), -tip.z(), -exact.z(), (tip - exact).norm(), 100 * energy, -100 * delta);
    }
  }
}

// Part of a shell turned rigidly (prescribed control points); the rest must follow, strain free.
void rigid_rotations() {
  std::printf("\n### Rigid rotations: part of the shell turned by prescribed control points\n\n");
  std::printf("| shell | turn | off rigid / size | strain energy | linear model: off rigid / size | iterations |\n");
  std::printf("|---|---|---|---|---|---|\n");
  const Material material{2.0e9, 0.35, 0.002, 1000.0};
  auto run = [&](const char* name, const ControlMesh& mesh, const std::vector<int32_t>& held, const Vec3& axis,
                 const Vec3& through) {
    auto model = ShellModel::build(mesh, material).value();
    auto cache = std::make_shared<FactorCache>();
    Solver linear(model, cache);
    NonlinearSolver nonlinear(model, cache);
    const double size = mesh.bounding_diagonal();
    for (double degrees : {30.0, 90.0, 180.0}) {
      const Eigen::Matrix3d r = Eigen::AngleAxisd(degrees * M_PI / 180.0, axis.normalized()).toRotationMatrix();
      auto rigid = [&](int32_t v) { return test::rigid_turn(r, through, mesh.positions()[static_cast<size_t>(v)]); };
      DeformationRequest request;
      for (int32_t v : held) request.vertex_constraints.push_back({v, kAxisAll, rigid(v)});
      auto solution = nonlinear.solve(request);
      auto lin = linear.solve(request);
      if (!solution.ok() || !lin.ok()) {
        std::printf("| %s | %.0f° | refused |\n", name, degrees);
        continue;
      }
      double worst = 0.0, linear_worst = 0.0;
      for (int32_t v = 0; v < mesh.num_vertices(); ++v) {
        worst = std::max(worst, (solution->displacement.segment<3>(3 * v) - rigid(v)).norm());
        linear_worst = std::max(linear_worst, (lin->displacement.segment<3>(3 * v) - rigid(v)).norm());
      }
      std::printf("| %s | %.0f° | %.1e | %.1e J | %.2f | %d |\n", name, degrees, worst / size,
                  solution->stats.strain_energy, linear_worst / size, solution->stats.iterations);
    }
  };
  const ControlMesh plate = test::make_grid(8, 4, 0.8, 0.4);
  std::vector<int32_t> held;
  for (int j = 0; j <= 4; ++j) {
    for (int i = 0; i <= 1; ++i) held.push_back(test::grid_index(8, i, j));
  }
  run("flat plate 8x4", plate, held, Vec3(0.0, 1.0, 0.0), Vec3(0.05, 0.0, 0.0));
  const ControlMesh helmet = test::load_asset_mesh("catmark_helmet.obj");
  std::vector<int32_t> order(static_cast<size_t>(helmet.num_vertices()));
  for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int32_t>(i);
  std::sort(order.begin(), order.end(), [&](int32_t a, int32_t b) {
    return helmet.positions()[static_cast<size_t>(a)].x() < helmet.positions()[static_cast<size_t>(b)].x();
  });
  order.resize(order.size() / 5);
  run("catmark_helmet", helmet, order, Vec3(0.3, 1.0, 0.5), helmet.positions()[static_cast<size_t>(order[0])]);
}

// Small loads: the nonlinear answer tends to the linear one, the difference linear in the load.
void small_loads() {
  std::printf("\n### Small loads: nonlinear against linear (|u_nl - u_lin| / |u_lin|)\n\n");
  std::printf("| shell | load | linear: measure | nonlinear | relative difference | ratio to the previous row |\n");
  std::printf("|---|---|---|---|---|---|\n");
  auto run = [](const char* name, const ControlMesh& mesh, const Material& material,
                const std::function<DeformationRequest(double)>& request, const std::vector<double>& loads,
                const std::function<double(const ShellModel&, const Eigen::VectorXd&)>& measure) {
    auto model = ShellModel::build(mesh, material).value();
    auto cache = std::make_shared<FactorCache>();
    Solver linear(model, cache);
    NonlinearSolver nonlinear(model, cache);
    double previous = 0.0;
    for (double load : loads) {
      auto lin = linear.solve(request(load));
      auto non = nonlinear.solve(request(load));
      if (!lin.ok() || !non.ok()) {
        std::printf("| %s | %g | refused: %s |\n", name, load, non.ok() ? "" : non.error().message.c_str());
        continue;
      }
      const double d = (non->displacement - lin->displacement).norm() / lin->displacement.norm();
      std::printf("| %s | %g | %.6g | %.6g | %.3e | %s |\n", name, load, measure(*model, lin->displacement),
                  measure(*model, non->displacement), d, previous > 0 ? std::to_string(d / previous).c_str() : "");
      previous = d;
    }
  };
  // The clamped strip of nonlinear_solver_test.cpp: tip deflection.
  const ControlMesh strip = test::make_grid(8, 4, 0.4, 0.2);
  const SurfacePoint tip{8 * 2 - 1, 0, 1.0, 0.0};
  run(
      "clamped strip 8x4, tip -w (m)", strip, Material{2.0e9, 0.35, 0.002, 1000.0},
      [&](double load) {
        DeformationRequest r;
        for (int j = 0; j <= 4; ++j) {
          for (int i = 0; i <= 1; ++i) r.vertex_constraints.push_back({test::grid_index(8, i, j), kAxisAll, Vec3::Zero()});
        }
        r.surface_forces.push_back({tip, Vec3(0.0, 0.0, -load)});
        return r;
      },
      {0.1, 0.01, 0.001}, [&](const ShellModel& m, const Eigen::VectorXd& u) { return -limit_displacement(m, u, tip).z(); });
  // The open hemisphere (16 x 16 quarter): P in the linear range, radial displacement at A. At
  // P = 2 (the quarter carries 1 at each load point) the linear value is the linear benchmark's
  // (MacNeal and Harder 1985: 0.094).
  const test::OpenHemisphere h = test::make_open_hemisphere(16, 16);
  run(
      "hemisphere 16x16, u_A", h.grid.mesh, test::OpenHemisphere::material(),
      [&](double load) { return h.request(load); }, {2.0, 0.2, 0.02},
      [&](const ShellModel& m, const Eigen::VectorXd& u) { return limit_displacement(m, u, h.a()).x(); });
}

// A Sze, Liu and Lo curve: every tabulated load in turn, each solve from the previous answer.
template <class Benchmark, class Measure>
void sze_curve(const char* title, const char* columns, const std::vector<std::pair<int, int>>& levels,
               const test::SzeRow* rows, size_t n, int count, Measure measure, const std::vector<double>& printed) {
  std::printf("\n### %s\n\n| mesh | P/Pmax | %s | iterations | ms |\n|---|---|", title, columns);
  for (int c = 0; c < 3 * count + 2; ++c) std::printf("---|");
  std::printf("\n");
  for (auto [nu, nv] : levels) {
    const Benchmark bench = Benchmark::make(nu, nv);
    auto model = ShellModel::build(bench.grid.mesh, Benchmark::material()).value();
    NonlinearSolver solver(model, std::make_shared<FactorCache>());
    Eigen::VectorXd u = Eigen::VectorXd::Zero(model->num_dofs());
    for (size_t k = 0; k < n; ++k) {
      const auto t0 = bench::Clock::now();
      auto solution = solver.solve(bench.request(rows[k].load_fraction * Benchmark::kMaxLoad), u);
      const double ms = bench::ms_since(t0);
      if (!solution.ok()) {
        std::printf("| %dx%d | %.3f | refused: %s |\n", nu, nv, rows[k].load_fraction, solution.error().message.c_str());
        break;
      }
      u = solution->displacement;
      bool print = false;
      for (double p : printed) print = print || std::abs(p - rows[k].load_fraction) < 1e-9;
      if (!print) continue;
      const Vec3 m = measure(bench, *model, u);
      const double ref[3] = {rows[k].first, rows[k].second, rows[k].third};
      std::printf("| %dx%d | %.3f |", nu, nv, rows[k].load_fraction);
      for (int c = 0; c < count; ++c) std::printf(" %.3f | %.3f | %+.2f%% |", m[c], ref[c], 100 * (m[c] / ref[c] - 1));
      std::printf(" %d | %.0f |\n", solution->stats.iterations, ms);
    }
  }
}

struct Cylinder : test::PulloutCylinder {
  static Cylinder make(int nt, int nl) { return Cylinder{test::make_pullout_cylinder(nt, nl)}; }
};
struct Hemisphere : test::OpenHemisphere {
  static Hemisphere make(int nphi, int npsi) { return Hemisphere{test::make_open_hemisphere(nphi, npsi)}; }
};

}  // namespace
}  // namespace softshell::engine

int main(int argc, char** argv) {
  using namespace softshell::engine;
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  std::printf("# bench_nonlinear_reference%s: %s\n", quick ? " --quick" : "", softshell::bench::machine().c_str());
  cantilever_against_the_elastica(quick ? std::vector<int>{8, 16} : std::vector<int>{8, 16, 32});
  end_moment(quick ? std::vector<int>{16, 32} : std::vector<int>{16, 32, 64});
  rigid_rotations();
  small_loads();
  const std::vector<double> printed = {0.05, 0.1, 0.25, 0.5, 0.525, 0.75, 1.0};
  sze_curve<Cylinder>("Pulled-out open cylinder (Sze, Liu, Lo 2004, section 3.5): octant, ours beside their 24x36 mesh",
                      "w_A | Sze | diff | -u_B | Sze | diff | -u_C | Sze | diff",
                      quick ? std::vector<std::pair<int, int>>{{12, 8}, {24, 16}}
                            : std::vector<std::pair<int, int>>{{12, 8}, {24, 16}, {48, 32}},
                      softshell::test::kSzePulloutCylinder, std::size(softshell::test::kSzePulloutCylinder), 3,
                      [](const Cylinder& c, const ShellModel& m, const Eigen::VectorXd& u) {
                        return softshell::Vec3(limit_displacement(m, u, c.a()).z(), -limit_displacement(m, u, c.b()).x(),
                                               -limit_displacement(m, u, c.c()).x());
                      },
                      printed);
  sze_curve<Hemisphere>("Hemisphere with an 18° hole (Sze, Liu, Lo 2004, section 3.4): quarter, ours beside their 16x16 mesh",
                        "u_A (out) | Sze | diff | -u_B (in) | Sze | diff",
                        quick ? std::vector<std::pair<int, int>>{{8, 8}, {16, 16}}
                              : std::vector<std::pair<int, int>>{{8, 8}, {16, 16}, {32, 32}},
                        softshell::test::kSzeHemisphere, std::size(softshell::test::kSzeHemisphere), 2,
                        [](const Hemisphere& h, const ShellModel& m, const Eigen::VectorXd& u) {
                          return softshell::Vec3(limit_displacement(m, u, h.a()).x(), -limit_displacement(m, u, h.b()).y(), 0.0);
                        },
                        printed);
  return 0;
}
