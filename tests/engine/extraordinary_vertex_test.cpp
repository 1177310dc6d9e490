// The shell at extraordinary vertices (EVs), checked against exact answers: the membrane patch
// test, a pressure on closed surfaces, simply supported plates against Navier's series, and the
// quadrature of quads next to non-quads. Each test prints its table.
#include <cmath>
#include <cstdio>
#include <map>
#include <set>

#include <gtest/gtest.h>

#include "shell_benchmarks.h"
#include "softshell/engine/solver.h"
#include "softshell/engine/stresses.h"
#include "test_meshes.h"

namespace softshell::engine {
namespace {

// A flat mesh, u = G X prescribed at the boundary control points (the boundary curves depend on
// those alone), no load: the exact answer is u = G X everywhere (an affine field is in the
// space, has constant membrane strain and no bending). max |u - G X| / max |G X|.
double patch_test_error(const ControlMesh& mesh, int ev_levels) {
  PrecomputeOptions options;
  options.quadrature.ev_refinement_levels = ev_levels;
  auto model = ShellModel::build(mesh, Material{1.0e6, 0.3, 0.01, 1.0}, options).value();
  Eigen::Matrix3d g;
  g << 0.011, 0.023, -0.004, 0.003, -0.012, 0.005, 0.002, 0.0013, 0.0;  // in-plane and out-of-plane parts
  const std::vector<char> boundary = test::boundary_points(mesh);
  DeformationRequest request;
  for (int32_t v = 0; v < mesh.num_vertices(); ++v) {
    if (boundary[static_cast<size_t>(v)]) request.vertex_constraints.push_back({v, kAxisAll, g * mesh.positions()[static_cast<size_t>(v)]});
  }
  Solver solver(model, std::make_shared<FactorCache>());
  auto solution = solver.solve(request);
  EXPECT_TRUE(solution.ok()) << solution.error().message;
  if (!solution.ok()) return 1.0;
  double error = 0.0, scale = 0.0;
  for (int32_t v = 0; v < mesh.num_vertices(); ++v) {
    const Vec3 exact = g * mesh.positions()[static_cast<size_t>(v)];
    error = std::max(error, (solution->displacement.segment<3>(3 * v) - exact).norm());
    scale = std::max(scale, exact.norm());
  }
  return error / scale;
}

TEST(ExtraordinaryVertices, MembranePatchTest) {
  struct Case {
    const char* name;
    ControlMesh mesh;
  };
  std::vector<Case> cases = {{"valence 3", test::fan_plate(3, 3)},
                             {"valence 5", test::fan_plate(5, 3)},
                             {"valence 6", test::fan_plate(6, 3)},
                             {"boundary, 3 faces", test::fan_plate(4, 3, 3)},
                             {"triangle", test::ngon_plate(3, 2)},
                             {"pentagon", test::ngon_plate(5, 2)}};
  for (size_t i = 0; i < cases.size(); ++i) test::perturb_interior(cases[i].mesh, 0.15, 7u + static_cast<unsigned>(i));
  std::printf("\nMembrane patch test, max |u - G X| / max |G X| by EV refinement levels\n%20s", "mesh");
  const std::vector<int> levels = {3, 4, 5, 6};
  for (int l : levels) std::printf("  %9d", l);
  std::printf("\n");
  for (const Case& c : cases) {
    std::printf("%20s", c.name);
    for (int l : levels) {
      const double error = patch_test_error(c.mesh, l);
      std::printf("  %9.2e", error);
      if (l == 6) {
        EXPECT_LT(error, 1e-9) << c.name;
      }
    }
    std::printf("\n");
  }
}

// Integral of n dA over a closed surface is zero; the engine's pressure load sums to p times it.
TEST(ExtraordinaryVertices, PressureOnClosedSurfacesHasNoResultant) {
  for (const char* name : {"spot_control_mesh.obj", "blub_control_mesh.obj", "catmark_torus.obj", "catmark_cube.obj"}) {
    auto model = ShellModel::build(test::load_asset_mesh(name), Material{1.0e6, 0.3, 0.01, 1.0}).value();
    DeformationRequest request;
    request.pressure = 1.0;
    const Eigen::VectorXd f = model->load_vector(request);
    Vec3 net = Vec3::Zero();
    for (int32_t v = 0; v < model->num_control_points(); ++v) net += f.segment<3>(3 * v);
    std::printf("%s: net pressure force / (p A) = %.2e\n", name, net.norm() / model->area());
    EXPECT_LT(net.norm(), 1e-10 * model->area()) << name;
  }
}

// Centre deflection of a simply supported square plate under a uniform load, on plates of n x n
// faces with two blocks of extraordinary vertices each (their size shrinks with the faces).
TEST(ExtraordinaryVertices, SimplySupportedPlateConvergesAtSecondOrder) {
  constexpr double kE = 1.0e7, kNu = 0.3, kT = 0.01, kA = 1.0;
  const double d = kE * kT * kT * kT / (12.0 * (1.0 - kNu * kNu));
  std::printf("\nSimply supported plate with EVs: w D / (q a^4), Navier %.12f\n", test::kNavierCentreDeflection);
  std::printf("%8s %14s %10s %6s\n", "faces", "coefficient", "error", "rate");
  double previous = 0.0;
  for (int n : {8, 16, 32}) {
    const test::EvPlate plate = test::make_ev_plate(n, kA);
    auto model = ShellModel::build(plate.mesh, Material{kE, kNu, kT, 0.0}).value();
    const std::vector<char> boundary = test::boundary_points(plate.mesh);
    DeformationRequest request;
    for (int32_t v = 0; v < plate.mesh.num_vertices(); ++v) {
      request.vertex_constraints.push_back(
          {v, boundary[static_cast<size_t>(v)] ? uint32_t{kAxisAll} : uint32_t{kAxisX | kAxisY}, Vec3::Zero()});
    }
    request.surface_load = Vec3(0.0, 0.0, -1.0);
    Solver solver(model, std::make_shared<FactorCache>());
    auto solution = solver.solve(request);
    ASSERT_TRUE(solution.ok()) << solution.error().message;
    const LimitSample centre = model->evaluator().evaluate(plate.centre);
    ASSERT_LT((centre.position - Vec3(0.5, 0.5, 0.0)).norm(), 1e-12);
    const LimitStencil st = model->evaluator().stencil(plate.centre);
    double w = 0.0;
    for (size_t k = 0; k < st.size(); ++k) w += st.position[k] * solution->displacement[3 * st.indices[k] + 2];
    const double coefficient = -w * d / (kA * kA * kA * kA);
    const double error = std::abs(coefficient / test::kNavierCentreDeflection - 1.0);
    const double rate = previous > 0.0 ? std::log2(previous / error) : 0.0;
    std::printf("%5dx%-3d %14.10f %10.3e %6.2f\n", n, n, coefficient, error, rate);
    if (previous > 0.0) {
      EXPECT_GT(rate, 1.9) << n;
    }
    previous = error;
  }
}

// A quad whose corners are regular but touch a triangle is 2 x 2 bicubic pieces: one Gauss rule
// per piece, not one per face. The face is found in spot's control mesh.
TEST(ExtraordinaryVertices, QuadsNextToNonQuadsAreIntegratedPerPiece) {
  const ControlMesh mesh = test::load_asset_mesh("spot_control_mesh.obj");
  std::vector<int> faces_of(static_cast<size_t>(mesh.num_vertices()), 0);
  std::vector<char> next_to_non_quad(static_cast<size_t>(mesh.num_vertices()), 0);
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    for (int32_t v : mesh.face(f)) {
      ++faces_of[static_cast<size_t>(v)];
      if (mesh.face_size(f) != 4) next_to_non_quad[static_cast<size_t>(v)] = 1;
    }
  }
  std::set<int32_t> wanted;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    if (mesh.face_size(f) != 4) continue;
    bool regular_corners = true, touches = false;
    for (int32_t v : mesh.face(f)) {
      regular_corners &= faces_of[static_cast<size_t>(v)] == 4;
      touches |= next_to_non_quad[static_cast<size_t>(v)] != 0;
    }
    if (regular_corners && touches) wanted.insert(f);
  }
  ASSERT_FALSE(wanted.empty());
  PrecomputeOptions options;
  options.quadrature.max_cell_distortion = 0.0;  // only the structural cells
  auto model = ShellModel::build(mesh, Material{1.0e6, 0.3, 0.01, 1.0}, options).value();
  std::map<int32_t, std::set<double>> u_values;
  for (const QuadraturePoint& q : model->quadrature()) {
    if (wanted.count(q.point.face)) u_values[q.point.face].insert(q.point.u);
  }
  for (int32_t f : wanted) EXPECT_EQ(u_values[f].size(), 8u) << "face " << f;  // two cells of 4 x 4 along u
}

// At an extraordinary vertex itself the curvature vanishes or diverges: the stress is that of
// the field next to it (finite, and the same from every face around the vertex up to the
// field's variation over 2^-10 of a face), at the vertex's position.
TEST(ExtraordinaryVertices, StressAtTheVertexIsTheStressNextToIt) {
  const ControlMesh mesh = test::fan_plate(5, 2);
  auto model = ShellModel::build(mesh, Material{1.0e6, 0.3, 0.01, 1.0}).value();
  const std::vector<char> boundary = test::boundary_points(mesh);
  DeformationRequest request;
  for (int32_t v = 0; v < mesh.num_vertices(); ++v) {
    if (boundary[static_cast<size_t>(v)]) request.vertex_constraints.push_back({v, kAxisAll, Vec3::Zero()});
  }
  request.surface_load = Vec3(0.0, 0.0, -1.0);
  Solver solver(model, std::make_shared<FactorCache>());
  const Eigen::VectorXd u = solver.solve(request).value().displacement;
  double low = 1e300, high = 0.0;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    if (mesh.face(f)[0] != 0) continue;  // the faces at the vertex, corner 0
    const StressSample at = evaluate_stress(*model, u, {f, 0, 0.0, 0.0});
    const StressSample next = evaluate_stress(*model, u, {f, 0, 1.0 / 1024.0, 1.0 / 1024.0});
    EXPECT_LT(at.position.norm(), 1e-12);  // the vertex's limit point (the fan is symmetric)
    EXPECT_EQ(at.von_mises(), next.von_mises());
    EXPECT_GT(at.von_mises(), 0.0);
    low = std::min(low, at.von_mises());
    high = std::max(high, at.von_mises());
  }
  EXPECT_LT(high - low, 0.05 * high);  // the same field seen from five faces
}

}  // namespace
}  // namespace softshell::engine
