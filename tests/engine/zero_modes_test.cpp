// The zero-energy modes of a model: found on the basis' Gram matrix, so they depend neither on
// the thickness nor on the material, for every part size.
#include "zero_modes.h"

#include <gtest/gtest.h>

#include "shell_benchmarks.h"
#include "softshell/engine/shell_model.h"
#include "test_meshes.h"

namespace softshell::engine {
namespace {

std::shared_ptr<const ShellModel> build(const ControlMesh& mesh, double youngs, double thickness) {
  auto model = ShellModel::build(mesh, Material{youngs, 0.3, thickness, 0.0});
  EXPECT_TRUE(model.ok()) << model.error().message;
  return model.ok() ? *model : nullptr;
}

// |K z| against |K| |z|, the largest over the DOFs (round-off for a true zero-energy mode).
double relative_energy_residual(const ShellModel& model, const Eigen::VectorXd& z) {
  const Eigen::SparseMatrix<double>& k = model.stiffness();
  const Eigen::VectorXd kz = k * z;
  double worst = 0.0;
  for (Eigen::Index i = 0; i < k.cols(); ++i) {
    double size = 0.0;
    for (Eigen::SparseMatrix<double>::InnerIterator it(k, i); it; ++it) size += std::abs(it.value() * z[it.row()]);
    if (size > 0.0) worst = std::max(worst, std::abs(kz[i]) / size);
  }
  return worst;
}

TEST(ZeroModes, DoNotDependOnThicknessOrMaterial) {
  struct Case {
    const char* name;
    ControlMesh mesh;
    Eigen::Index modes;
  };
  const std::vector<Case> cases = {
      {"plate 1x1", test::make_plate(1, 1.0).mesh, 6},
      {"plate 12x12", test::make_plate(12, 1.0).mesh, 6},
      {"ghost-ringed plate 1x1", test::make_plate(1, 1.0, true).mesh, 6},
      {"ghost-ringed strip 16x4", test::make_rectangle(16, 4, 1.0, 0.25, true).mesh, 6},
      {"cube (valence 3 everywhere: one checkerboard mode per axis)", test::load_asset_mesh("catmark_cube.obj"), 9},
      {"helmet", test::load_asset_mesh("catmark_helmet.obj"), 6},
  };
  for (const Case& c : cases) {
    for (double t : {1e-1, 1e-3, 1e-6}) {
      for (double e : {1.0, 2e11}) {
        auto model = build(c.mesh, e, t);
        ASSERT_TRUE(model);
        const Eigen::MatrixXd& modes = model->zero_energy_modes();
        EXPECT_EQ(modes.cols(), c.modes) << c.name << ", t = " << t << ", E = " << e;
        for (Eigen::Index m = 0; m < modes.cols(); ++m) {
          EXPECT_LT(relative_energy_residual(*model, modes.col(m)), 1e-12) << c.name << ", mode " << m << ", t = " << t;
        }
      }
    }
  }
}

// A matrix like a scaled Gram matrix with a known null space: k disjoint cliques of 5 (each a
// normalized Laplacian: eigenvalues 0 and 5/4), too large for the dense path when asked.
Eigen::SparseMatrix<double> cliques(int count, bool joined) {
  std::vector<Eigen::Triplet<double>> t;
  const int n = 5 * count;
  for (int c = 0; c < count; ++c) {
    for (int i = 0; i < 5; ++i) {
      for (int j = 0; j < 5; ++j) t.emplace_back(5 * c + i, 5 * c + j, i == j ? 1.0 : -0.25);
    }
  }
  Eigen::SparseMatrix<double> a(n, n);
  a.setFromTriplets(t.begin(), t.end());
  if (joined) a += 0.2 * Eigen::SparseMatrix<double>(Eigen::VectorXd::Ones(n).asDiagonal());  // positive definite
  return a;
}

TEST(ZeroModes, SubspaceIterationFindsTheNullSpaceOfLargeParts) {
  for (int count : {3, 100}) {
    const Eigen::SparseMatrix<double> a = cliques(count, false);
    const Eigen::MatrixXd dense = internal::null_space_of_scaled_gram(a, 1000);
    const Eigen::MatrixXd iterated = internal::null_space_of_scaled_gram(a, 0);
    ASSERT_EQ(dense.cols(), count);
    ASSERT_EQ(iterated.cols(), count);
    const Eigen::MatrixXd residual = a * iterated;
    EXPECT_LT(residual.norm(), 1e-12);
    EXPECT_LT((iterated.transpose() * iterated - Eigen::MatrixXd::Identity(count, count)).norm(), 1e-12);
    // The same space: the projection of one basis on the other keeps it.
    EXPECT_LT((dense - iterated * (iterated.transpose() * dense)).norm(), 1e-10);
  }
  EXPECT_EQ(internal::null_space_of_scaled_gram(cliques(100, true), 0).cols(), 0);
}

// Two plates joined by one face that has no limit surface (boundary "none"): each could move
// rigidly on its own, which no rigid mode of the whole part describes. Refused, with the reason.
TEST(ZeroModes, PartsWhoseSurfaceFallsApartAreRefused) {
  // Two 4 x 4 grids of faces side by side, joined by a single face between their middle rows.
  std::vector<Vec3> positions;
  std::vector<std::vector<int32_t>> faces;
  auto grid = [&](double x0) {
    const auto first = static_cast<int32_t>(positions.size());
    for (int j = 0; j <= 4; ++j) {
      for (int i = 0; i <= 4; ++i) positions.emplace_back(x0 + i, j, 0.0);
    }
    for (int j = 0; j < 4; ++j) {
      for (int i = 0; i < 4; ++i) {
        const int32_t a = first + j * 5 + i;
        faces.push_back({a, a + 1, a + 6, a + 5});
      }
    }
    return first;
  };
  const int32_t left = grid(0.0), right = grid(5.0);
  faces.push_back({left + 2 * 5 + 4, right + 2 * 5, right + 3 * 5, left + 3 * 5 + 4});
  ControlMesh mesh(positions, faces);
  mesh.set_boundary(BoundaryMode::kNone);
  auto model = ShellModel::build(mesh, Material{1e9, 0.3, 0.01, 0.0});
  ASSERT_FALSE(model.ok());
  EXPECT_EQ(model.error().code, ErrorCode::kUnprocessable);
  EXPECT_NE(model.error().message.find("falls apart"), std::string::npos) << model.error().message;
}

}  // namespace
}  // namespace softshell::engine
