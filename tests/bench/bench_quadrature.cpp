// The quadrature against cost, and the EV convergence table.
//
// Part 1: on meshes with extraordinary vertices (EVs) and with strongly non-uniform faces, the
// compliance f.u of a fixed load case against a converged reference (6 x 6 Gauss points, 8
// refinement levels toward every EV, cells split until nearly uniform), for the Gauss order, the
// EV refinement levels and distortion splitting. (The limit surface itself is exact; only its
// integration varies.)
//
// Part 2, the EV convergence table: the membrane patch test (exact answer: an affine field) on
// flat meshes with EVs by EV refinement levels, the resultant of a pressure on closed meshes,
// the centre deflection of simply supported plates with EVs against Navier's series, and the
// precompute time of catmark_righthanded by EV refinement levels.
//
// Usage: bench_quadrature [mesh.obj ...]   (part 1 on those meshes only, no part 2)
#include <cmath>
#include <cstdio>
#include <ctime>
#include <string>
#include <vector>

#include "bench_support.h"
#include "shell_benchmarks.h"
#include "softshell/engine/solver.h"
#include "softshell/level_of_detail.h"
#include "test_meshes.h"

using namespace softshell;

namespace {

struct Case {
  ControlMesh mesh;
  DeformationRequest request;
};

Case make_case(const std::string& name) {
  Case c;
  c.mesh = test::load_asset_mesh(name);  // crease tags are ignored: the simulated surface is smooth
  const double scale = 1.0 / c.mesh.bounding_diagonal();
  for (Vec3& p : c.mesh.positions()) p *= scale;
  // Held at the control points of face 0; loaded by pressure and a point force.
  for (int32_t v : c.mesh.face(0)) c.request.vertex_constraints.push_back({v, kAxisAll, Vec3::Zero()});
  c.request.pressure = 1000.0;
  c.request.surface_forces.push_back({{c.mesh.num_faces() / 2, 0, 0.5, 0.5}, Vec3(0.0, 0.0, -10.0)});
  return c;
}

double compliance(const Case& c, const engine::PrecomputeOptions& options, double& build_ms) {
  const auto t0 = bench::Clock::now();
  auto model = engine::ShellModel::build(c.mesh, Material{6.9e10, 0.33, 0.002, 2700.0}, options).value();
  build_ms = bench::ms_since(t0);
  engine::Solver solver(model, std::make_shared<engine::FactorCache>());
  auto solution = solver.solve(c.request).value();
  return model->load_vector(c.request).dot(solution.displacement);
}

void print_row(const char* label, const Case& c, const engine::PrecomputeOptions& o, double ref) {
  double ms = 0.0;
  const double value = compliance(c, o, ms);
  std::printf("%s | %.1f ms | %.2e |\n", label, ms, std::abs(value / ref - 1.0));
}

void quadrature_study(const std::string& name) {
  const Case c = make_case(name);
  engine::PrecomputeOptions reference;
  reference.quadrature.gauss_points = 6;
  reference.quadrature.ev_refinement_levels = 8;
  reference.quadrature.max_cell_distortion = 1.25;
  reference.quadrature.max_distortion_splits = 5;
  double ref_ms = 0.0;
  const double ref = compliance(c, reference, ref_ms);
  engine::PrecomputeOptions check = reference;
  check.quadrature.gauss_points = 8;
  double check_ms = 0.0;
  const double check_value = compliance(c, check, check_ms);
  std::printf("\n%s (reference %.0f ms; with 8 x 8 Gauss points it changes by %.1e)\n\n", name.c_str(), ref_ms,
              std::abs(check_value / ref - 1.0));

  std::printf("Without distortion splitting:\n\n");
  std::printf("| Gauss points | EV refinement levels | precompute | compliance error |\n");
  std::printf("| ---: | ---: | ---: | ---: |\n");
  for (int gauss : {3, 4, 5}) {
    for (int levels : {0, 1, 2, 3, 4, 5, 6}) {
      if (gauss != 4 && levels != 4) continue;  // keep the table readable
      engine::PrecomputeOptions o;
      o.quadrature.gauss_points = gauss;
      o.quadrature.ev_refinement_levels = levels;
      o.quadrature.max_cell_distortion = 0.0;
      char label[64];
      std::snprintf(label, sizeof label, "| %d | %d", gauss, levels);
      print_row(label, c, o, ref);
    }
  }
  std::printf("\n4 x 4 points, 4 EV levels with distortion splitting (the default: 4):\n\n");
  std::printf("| max cell distortion | max splits | precompute | compliance error |\n");
  std::printf("| ---: | ---: | ---: | ---: |\n");
  for (double distortion : {0.0, 8.0, 4.0, 2.0, 1.5}) {
    engine::PrecomputeOptions o;
    o.quadrature.max_cell_distortion = distortion;
    char label[64];
    std::snprintf(label, sizeof label, "| %s | %d", distortion == 0.0 ? "off" : std::to_string(distortion).substr(0, 3).c_str(),
                  o.quadrature.max_distortion_splits);
    print_row(label, c, o, ref);
  }
  std::fflush(stdout);
}

// Membrane patch test: u = G X at the boundary control points, exact answer u = G X everywhere.
double patch_test_error(const ControlMesh& mesh, int ev_levels, double& build_ms) {
  engine::PrecomputeOptions options;
  options.quadrature.ev_refinement_levels = ev_levels;
  const auto t0 = bench::Clock::now();
  auto model = engine::ShellModel::build(mesh, Material{1.0e6, 0.3, 0.01, 1.0}, options).value();
  build_ms = bench::ms_since(t0);
  Eigen::Matrix3d g;
  g << 0.011, 0.023, -0.004, 0.003, -0.012, 0.005, 0.002, 0.0013, 0.0;
  const std::vector<char> boundary = test::boundary_points(mesh);
  DeformationRequest request;
  for (int32_t v = 0; v < mesh.num_vertices(); ++v) {
    if (boundary[static_cast<size_t>(v)]) request.vertex_constraints.push_back({v, kAxisAll, g * mesh.positions()[static_cast<size_t>(v)]});
  }
  engine::Solver solver(model, std::make_shared<engine::FactorCache>());
  auto solution = solver.solve(request).value();
  double error = 0.0, scale = 0.0;
  for (int32_t v = 0; v < mesh.num_vertices(); ++v) {
    const Vec3 exact = g * mesh.positions()[static_cast<size_t>(v)];
    error = std::max(error, (solution.displacement.segment<3>(3 * v) - exact).norm());
    scale = std::max(scale, exact.norm());
  }
  return error / scale;
}

// Centre deflection coefficient w D / (q a^4) of a simply supported unit plate, q = 1.
double plate_coefficient(const ControlMesh& mesh, const SurfacePoint& centre) {
  constexpr double kE = 1.0e7, kNu = 0.3, kT = 0.01;
  auto model = engine::ShellModel::build(mesh, Material{kE, kNu, kT, 0.0}).value();
  const std::vector<char> boundary = test::boundary_points(mesh);
  DeformationRequest request;
  for (int32_t v = 0; v < mesh.num_vertices(); ++v) {
    request.vertex_constraints.push_back(
        {v, boundary[static_cast<size_t>(v)] ? uint32_t{kAxisAll} : uint32_t{kAxisX | kAxisY}, Vec3::Zero()});
  }
  request.surface_load = Vec3(0.0, 0.0, -1.0);
  engine::Solver solver(model, std::make_shared<engine::FactorCache>());
  auto solution = solver.solve(request).value();
  const LimitStencil st = model->evaluator().stencil(centre);
  double w = 0.0;
  for (size_t k = 0; k < st.size(); ++k) w += st.position[k] * solution.displacement[3 * st.indices[k] + 2];
  return -w * kE * kT * kT * kT / (12.0 * (1.0 - kNu * kNu));
}

void ev_convergence_table() {
  std::printf("\n## EV convergence table\n\nMembrane patch test, max |u - G X| / max |G X| (precompute of the largest mesh):\n\n");
  struct Mesh {
    const char* name;
    ControlMesh mesh;
  };
  std::vector<Mesh> meshes = {{"valence 3", test::fan_plate(3, 3)},     {"valence 5", test::fan_plate(5, 3)},
                              {"valence 6", test::fan_plate(6, 3)},     {"boundary, 3 faces", test::fan_plate(4, 3, 3)},
                              {"triangle", test::ngon_plate(3, 2)},     {"pentagon", test::ngon_plate(5, 2)}};
  for (size_t i = 0; i < meshes.size(); ++i) test::perturb_interior(meshes[i].mesh, 0.15, 7u + static_cast<unsigned>(i));
  std::printf("| EV refinement levels |");
  for (const Mesh& m : meshes) std::printf(" %s |", m.name);
  std::printf("\n| ---: |");
  for (size_t i = 0; i < meshes.size(); ++i) std::printf(" ---: |");
  std::printf("\n");
  for (int levels : {2, 3, 4, 5, 6, 7}) {
    std::printf("| %d |", levels);
    for (const Mesh& m : meshes) {
      double ms = 0.0;
      std::printf(" %.2e |", patch_test_error(m.mesh, levels, ms));
    }
    std::printf("\n");
  }

  std::printf("\nResultant of a unit pressure, |sum of f| / (p A):\n\n| mesh | resultant |\n| --- | ---: |\n");
  for (const char* name : {"spot_control_mesh.obj", "blub_control_mesh.obj", "catmark_torus.obj", "catmark_cube.obj"}) {
    auto model = engine::ShellModel::build(test::load_asset_mesh(name), Material{1.0e6, 0.3, 0.01, 1.0}).value();
    DeformationRequest request;
    request.pressure = 1.0;
    const Eigen::VectorXd f = model->load_vector(request);
    Vec3 net = Vec3::Zero();
    for (int32_t v = 0; v < model->num_control_points(); ++v) net += f.segment<3>(3 * v);
    std::printf("| %s | %.1e |\n", name, net.norm() / model->area());
  }

  std::printf("\nSimply supported plate with EVs, w D / (q a^4) against Navier %.12f:\n\n", test::kNavierCentreDeflection);
  std::printf("(a) n x n faces, two blocks of valence-3 and valence-5 EVs each (their size shrinks with h):\n\n");
  std::printf("| faces | coefficient | error | rate |\n| ---: | ---: | ---: | ---: |\n");
  double previous = 0.0;
  for (int n : {8, 16, 32, 64, 128}) {
    const test::EvPlate plate = test::make_ev_plate(n, 1.0);
    const double coefficient = plate_coefficient(plate.mesh, plate.centre);
    const double error = std::abs(coefficient / test::kNavierCentreDeflection - 1.0);
    std::printf("| %dx%d | %.10f | %.3e | %s |\n", n, n, coefficient, error,
                previous > 0.0 ? std::to_string(std::log2(previous / error)).substr(0, 4).c_str() : "");
    previous = error;
    std::fflush(stdout);
  }
  std::printf("\n(b) the 8 x 8 plate refined by Catmull-Clark (the same EVs, fixed in space):\n\n");
  std::printf("| levels | faces | error | rate |\n| ---: | ---: | ---: | ---: |\n");
  const test::EvPlate coarse = test::make_ev_plate(8, 1.0);
  previous = 0.0;
  for (int level = 1; level <= 5; ++level) {
    auto refinement = MeshRefinement::create(coarse.mesh, level).value();
    const double c = plate_coefficient(refinement.fine(), refinement.fine_point(coarse.centre).value());
    const double error = std::abs(c / test::kNavierCentreDeflection - 1.0);
    std::printf("| %d | %d | %.3e | %s |\n", level, refinement.fine().num_faces(), error,
                previous > 0.0 ? std::to_string(std::log2(previous / error)).substr(0, 4).c_str() : "");
    previous = error;
    std::fflush(stdout);
  }

  std::printf("\ncatmark_righthanded precompute by EV refinement levels (1 thread, CPU time, best of 5):\n\n");
  std::printf("| EV refinement levels | quadrature points | precompute |\n| ---: | ---: | ---: |\n");
  ControlMesh hand = test::load_asset_mesh("catmark_righthanded.obj");
  const double scale = 1.0 / hand.bounding_diagonal();
  for (Vec3& p : hand.positions()) p *= scale;
  for (int levels : {3, 4, 5, 6}) {
    double best = 1e300;
    size_t points = 0;
    for (int rep = 0; rep < 5; ++rep) {
      engine::PrecomputeOptions o;
      o.threads = 1;
      o.quadrature.ev_refinement_levels = levels;
      const std::clock_t t0 = std::clock();  // CPU time: less sensitive to a shared machine
      auto model = engine::ShellModel::build(hand, Material{6.9e10, 0.32, 0.002, 2700.0}, o).value();
      best = std::min(best, 1000.0 * static_cast<double>(std::clock() - t0) / CLOCKS_PER_SEC);
      points = model->quadrature().size();
    }
    std::printf("| %d | %zu | %.1f ms |\n", levels, points, best);
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::printf("softshell quadrature study on %s\n", bench::machine().c_str());
  std::vector<std::string> names = {"catmark_cube.obj", "spot_control_mesh.obj", "catmark_rook.obj", "catmark_pawn.obj",
                                    "catmark_righthanded.obj"};
  if (argc > 1) names.assign(argv + 1, argv + argc);
  for (const std::string& name : names) quadrature_study(name);
  if (argc <= 1) ev_convergence_table();
  return 0;
}
