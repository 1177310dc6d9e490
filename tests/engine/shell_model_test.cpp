#include "softshell/engine/shell_model.h"

#include <atomic>
#include <cstdio>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "softshell/engine/solver.h"
#include "test_meshes.h"

namespace softshell::engine {
namespace {

Material unit_material() { return Material{1.0e6, 0.3, 0.01, 1000.0}; }

std::shared_ptr<const ShellModel> build(const ControlMesh& mesh, PrecomputeOptions options = {}) {
  auto model = ShellModel::build(mesh, unit_material(), options);
  EXPECT_TRUE(model.ok()) << model.error().message;
  return model.ok() ? *model : nullptr;
}

// Rigid translations and the three infinitesimal rotations give zero strain energy.
TEST(ShellModel, RigidMotionsHaveNoStrain) {
  for (const char* name : {"catmark_cube.obj", "catmark_torus.obj", "catmark_tent.obj", "catmark_nonquads.obj",
                           "catmark_gregory_test5.obj", "catmark_helmet.obj", "spot_control_mesh.obj",
                           "penguin_control_mesh.obj"}) {
    ControlMesh mesh = test::load_asset_mesh(name);
    auto model = build(mesh);
    ASSERT_TRUE(model) << name;
    const Eigen::SparseMatrix<double>& k = model->stiffness();
    double k_norm = 0.0;
    for (Eigen::Index i = 0; i < k.nonZeros(); ++i) k_norm = std::max(k_norm, std::abs(k.valuePtr()[i]));
    const Eigen::MatrixXd& modes = model->rigid_modes();
    ASSERT_EQ(modes.cols(), 6 * model->num_components());
    for (Eigen::Index c = 0; c < modes.cols(); ++c) {
      const Eigen::VectorXd r = modes.col(c);
      const double residual = (k * r).cwiseAbs().maxCoeff() / (k_norm * r.cwiseAbs().maxCoeff());
      EXPECT_LT(residual, 1e-10) << name << " mode " << c;
    }
  }
}

TEST(ShellModel, StiffnessIsSymmetricPositiveSemidefiniteWithSixZeroModes) {
  for (const char* name : {"catmark_gregory_test5.obj", "catmark_torus.obj", "catmark_tent.obj", "catmark_helmet.obj"}) {
    auto model = build(test::load_asset_mesh(name));
    ASSERT_TRUE(model);
    const Eigen::MatrixXd k = Eigen::MatrixXd(model->stiffness());
    EXPECT_LT((k - k.transpose()).cwiseAbs().maxCoeff(), 1e-12 * k.cwiseAbs().maxCoeff()) << name;
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(k);
    const Eigen::VectorXd& values = eig.eigenvalues();
    const double top = values.maxCoeff();
    int zero = 0;
    for (Eigen::Index i = 0; i < values.size(); ++i) {
      EXPECT_GT(values[i], -1e-10 * top) << name;
      if (values[i] < 1e-10 * top) ++zero;
    }
    EXPECT_EQ(zero, 6) << name << ": smallest non-zero eigenvalue / largest = " << values[6] / top;
  }
}

// The cube's control mesh (every vertex of valence 3) has one extra zero-energy mode per axis:
// the checkerboard pattern +1/-1 on its two vertex classes, which one Catmull-Clark step maps to
// zero (the valence-3 vertex rule has no S term). Its limit surface does not move at all.
TEST(ShellModel, CubeCheckerboardModesDoNotMoveTheLimitSurface) {
  ControlMesh cube = test::load_asset_mesh("catmark_cube.obj");
  auto model = build(cube);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(Eigen::MatrixXd(model->stiffness()));
  const double top = eig.eigenvalues().maxCoeff();
  int zero = 0;
  for (Eigen::Index i = 0; i < eig.eigenvalues().size(); ++i) zero += eig.eigenvalues()[i] < 1e-10 * top;
  EXPECT_EQ(zero, 9);
  // Every zero mode outside the rigid ones leaves the limit surface where it is.
  const Eigen::MatrixXd& rigid = model->rigid_modes();
  for (Eigen::Index i = 0; i < 9; ++i) {
    Eigen::VectorXd mode = eig.eigenvectors().col(i);
    mode -= rigid * rigid.colPivHouseholderQr().solve(mode);  // remove the rigid part
    if (mode.norm() < 1e-6) continue;
    std::vector<Vec3> moved = cube.positions();
    for (size_t v = 0; v < moved.size(); ++v) moved[v] += mode.segment<3>(static_cast<Eigen::Index>(3 * v));
    for (int32_t f = 0; f < cube.num_faces(); ++f) {
      const SurfacePoint p{f, 0, 0.3, 0.6};
      EXPECT_LT((model->evaluator().evaluate(p, moved).position - model->evaluator().evaluate(p).position).norm(), 1e-12);
    }
  }
}

TEST(ShellModel, BitForBitTheSameForAnyThreadCount) {
  ControlMesh mesh = test::load_asset_mesh("spot_control_mesh.obj");
  PrecomputeOptions one, three;
  one.threads = 1;
  three.threads = 3;
  auto a = build(mesh, one), b = build(mesh, three);
  ASSERT_TRUE(a && b);
  ASSERT_EQ(a->stiffness().nonZeros(), b->stiffness().nonZeros());
  for (Eigen::Index i = 0; i < a->stiffness().nonZeros(); ++i) {
    ASSERT_EQ(a->stiffness().valuePtr()[i], b->stiffness().valuePtr()[i]);
  }
}

TEST(ShellModel, SurfaceLoadAddsUpToLoadTimesArea) {
  // A flat 2 x 1 sheet: the consistent load of q per unit area sums to q * area.
  ControlMesh mesh = test::make_grid(8, 4, 2.0, 1.0);
  auto model = build(mesh);
  ASSERT_TRUE(model);
  EXPECT_NEAR(model->area(), 2.0, 1e-12);
  DeformationRequest request;
  request.surface_load = Vec3(0.0, 0.0, -9.81);
  const Eigen::VectorXd f = model->load_vector(request);
  Vec3 total = Vec3::Zero();
  for (Eigen::Index i = 0; i < f.size() / 3; ++i) total += f.segment<3>(3 * i);
  EXPECT_NEAR(total.z(), -9.81 * 2.0, 1e-10);
  // Pressure on a closed surface has no resultant (the divergence theorem).
  auto sphere = build(test::load_asset_mesh("spot_control_mesh.obj"));
  request = DeformationRequest{};
  request.pressure = 100.0;
  const Eigen::VectorXd fp = sphere->load_vector(request);
  Vec3 resultant = Vec3::Zero();
  double magnitude = 0.0;
  for (Eigen::Index i = 0; i < fp.size() / 3; ++i) {
    resultant += fp.segment<3>(3 * i);
    magnitude += fp.segment<3>(3 * i).norm();
  }
  EXPECT_LT(resultant.norm(), 1e-3 * magnitude);
}

TEST(ShellModel, ReportsProgressAndCanBeCancelled) {
  ControlMesh mesh = test::load_asset_mesh("catmark_rook.obj");
  std::vector<double> progress;
  PrecomputeOptions options;
  options.threads = 2;
  options.progress = [&](double p) { progress.push_back(p); };
  ASSERT_TRUE(build(mesh, options));
  ASSERT_GE(progress.size(), 2u);
  EXPECT_TRUE(std::is_sorted(progress.begin(), progress.end()));
  EXPECT_DOUBLE_EQ(progress.back(), 1.0);

  std::atomic<bool> cancel{true};
  options.cancel = &cancel;
  auto cancelled = ShellModel::build(mesh, unit_material(), options);
  ASSERT_FALSE(cancelled.ok());
  EXPECT_EQ(cancelled.error().code, ErrorCode::kCancelled);
}

TEST(ShellModel, RejectsBadMaterialAndMeshWithReasons) {
  ControlMesh mesh = test::make_grid(2, 2);
  auto bad_e = ShellModel::build(mesh, Material{-1.0, 0.3, 0.01});
  ASSERT_FALSE(bad_e.ok());
  EXPECT_EQ(bad_e.error().code, ErrorCode::kUnprocessable);
  EXPECT_NE(bad_e.error().message.find("Young"), std::string::npos);
  auto bad_nu = ShellModel::build(mesh, Material{1e6, 0.5, 0.01});
  EXPECT_EQ(bad_nu.error().code, ErrorCode::kUnprocessable);
  ControlMesh broken({Vec3(0, 0, 0), Vec3(1, 0, 0)}, std::vector<std::vector<int32_t>>{{0, 1, 2}});
  auto bad_mesh = ShellModel::build(broken, unit_material());
  EXPECT_EQ(bad_mesh.error().code, ErrorCode::kInvalidArgument);
}

// A support loop (a row of control points squeezed next to another, as modellers do to sharpen an
// edge) makes the parametrization of the faces beside it strongly non-uniform; one Gauss rule per
// face then misjudges their stiffness. Distortion splitting must bring the answer to the
// converged one.
TEST(ShellModel, DistortedFacesAreSplitUntilTheirStiffnessConverges) {
  // A plate folded along x = 0.75 (column 6), with support loops at columns 5 and 7 squeezed to
  // 1/20 of the spacing on both sides of the fold.
  const int n = 8;
  const auto fold = [](double x, double) { return 0.3 * std::abs(x - 0.75); };
  ControlMesh mesh = test::make_grid(n, 4, 1.0, 0.5, fold);
  for (int j = 0; j <= 4; ++j) {
    for (int i : {5, 7}) {
      Vec3& p = mesh.positions()[static_cast<size_t>(test::grid_index(n, i, j))];
      p.x() = 0.75 + (i - 6) * 0.05 / n;
      p.z() = fold(p.x(), 0.0);
    }
  }
  DeformationRequest request;
  for (int j = 0; j <= 4; ++j) {
    for (int i = 0; i <= 1; ++i) request.vertex_constraints.push_back({test::grid_index(n, i, j), kAxisAll, Vec3::Zero()});
  }
  request.surface_forces.push_back({{n * 2 - 1, 0, 0.5, 0.5}, Vec3(0.0, 0.0, -1.0)});
  auto compliance = [&](const QuadratureOptions& quadrature) {
    PrecomputeOptions options;
    options.quadrature = quadrature;
    auto model = build(mesh, options);
    Solver solver(model, std::make_shared<FactorCache>());
    auto solution = solver.solve(request);
    EXPECT_TRUE(solution.ok()) << solution.error().message;
    return model->load_vector(request).dot(solution->displacement);
  };
  QuadratureOptions reference;
  reference.gauss_points = 6;
  reference.max_cell_distortion = 1.25;
  reference.max_distortion_splits = 5;
  QuadratureOptions off;
  off.max_cell_distortion = 0.0;
  const double exact = compliance(reference);
  const double unsplit = std::abs(compliance(off) / exact - 1.0);
  const double split = std::abs(compliance(QuadratureOptions{}) / exact - 1.0);
  std::printf("compliance error without splitting %.2e, with the default splitting %.2e\n", unsplit, split);
  EXPECT_GT(unsplit, 1e-3);  // the case is hard for a single rule per face
  EXPECT_LT(split, 0.1 * unsplit);

  QuadratureOptions bad;
  bad.max_cell_distortion = 0.5;
  PrecomputeOptions options;
  options.quadrature = bad;
  auto rejected = ShellModel::build(mesh, unit_material(), options);
  ASSERT_FALSE(rejected.ok());
  EXPECT_EQ(rejected.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(rejected.error().message.find("max_cell_distortion"), std::string::npos);
}

}  // namespace
}  // namespace softshell::engine
