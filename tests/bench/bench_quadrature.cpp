// Accuracy against cost of the quadrature and of Bfr's approximation level on meshes with
// extraordinary vertices. The quantity is the compliance f.u of a fixed load case; the reference
// uses 6x6 Gauss points, 6 refinement levels toward every irregular corner and approximation
// level 6. (The approximation level changes the surface itself, the refinement only how well it
// is integrated.)
#include <cstdio>

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

}  // namespace

int main() {
  std::printf("softshell quadrature study on %s\n", bench::machine().c_str());
  for (const char* name : {"catmark_cube.obj", "spot_control_mesh.obj", "catmark_rook.obj"}) {
    const Case c = make_case(name);
    engine::PrecomputeOptions reference;
    reference.quadrature.gauss_points = 6;
    reference.quadrature.ev_refinement_levels = 6;
    reference.evaluator.approx_level_smooth = 6;
    double ref_ms = 0.0;
    const double ref = compliance(c, reference, ref_ms);
    std::printf("\n%s (reference %.0f ms)\n\n", name, ref_ms);
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
          double ms = 0.0;
          const double value = compliance(c, o, ms);
          std::printf("| %d | %d | %d | %.1f ms | %.2e |\n", approx, gauss, levels, ms, std::abs(value / ref - 1.0));
        }
      }
    }
    std::fflush(stdout);
  }
  return 0;
}
