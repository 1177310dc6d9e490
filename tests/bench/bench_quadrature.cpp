// Accuracy against cost of the quadrature and of Bfr's approximation level on meshes with
// extraordinary vertices and with strongly non-uniform faces. The quantity is the compliance f.u
// of a fixed load case; the reference uses 6x6 Gauss points, 6 refinement levels toward every
// irregular corner, cells split until nearly uniform and approximation level 6. (The
// approximation level changes the surface itself, the quadrature only how well it is integrated.)
#include <cstdio>
#include <string>
#include <vector>

#include "bench_support.h"
#include "softshell/engine/solver.h"
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

}  // namespace

int main(int argc, char** argv) {
  std::printf("softshell quadrature study on %s\n", bench::machine().c_str());
  std::vector<std::string> names = {"catmark_cube.obj", "spot_control_mesh.obj", "catmark_rook.obj", "catmark_pawn.obj",
                                    "catmark_righthanded.obj"};
  if (argc > 1) names.assign(argv + 1, argv + argc);  // bench_quadrature [mesh.obj ...]
  for (const std::string& name : names) {
    const Case c = make_case(name);
    // The reference: a finer rule everywhere, cells split until the parametrization is nearly
    // uniform on each, and Bfr's patch tree 6 levels deep.
    engine::PrecomputeOptions reference;
    reference.quadrature.gauss_points = 6;
    reference.quadrature.ev_refinement_levels = 6;
    reference.quadrature.max_cell_distortion = 1.25;
    reference.quadrature.max_distortion_splits = 5;
    reference.evaluator.approx_level_smooth = 6;
    double ref_ms = 0.0;
    const double ref = compliance(c, reference, ref_ms);
    engine::PrecomputeOptions check = reference;
    check.quadrature.gauss_points = 8;
    double check_ms = 0.0;
    const double check_value = compliance(c, check, check_ms);
    std::printf("\n%s (reference %.0f ms; with 8 x 8 Gauss points it changes by %.1e)\n\n", name.c_str(), ref_ms,
                std::abs(check_value / ref - 1.0));

    std::printf("Without distortion splitting:\n\n");
    std::printf("| Bfr approx level | Gauss points | EV refinement levels | precompute | compliance error |\n");
    std::printf("| ---: | ---: | ---: | ---: | ---: |\n");
    for (int approx : {2, 3, 4}) {
      for (int gauss : {3, 4, 5}) {
        for (int levels : {0, 1, 2, 3, 4}) {
          if (gauss != 4 && levels != approx) continue;  // keep the table readable
          engine::PrecomputeOptions o;
          o.evaluator.approx_level_smooth = approx;
          o.quadrature.gauss_points = gauss;
          o.quadrature.ev_refinement_levels = levels;
          o.quadrature.max_cell_distortion = 0.0;
          char label[64];
          std::snprintf(label, sizeof label, "| %d | %d | %d", approx, gauss, levels);
          print_row(label, c, o, ref);
        }
      }
    }
    std::printf("\nApprox level 3, 4 x 4 points, 3 EV levels with distortion splitting (the default: 4):\n\n");
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
  return 0;
}
