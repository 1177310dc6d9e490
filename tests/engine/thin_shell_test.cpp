// Plates whose exact Kirchhoff answer lies in the spline space, from thick to very thin (t/L 1e-2
// .. 1e-6) and from one face to 32 x 8: the discrete answer must be the exact one to round-off,
// never a refusal (the answer is unique) and never a wrong answer. Each test prints its sweep.
#include <cmath>
#include <cstdio>

#include <gtest/gtest.h>

#include "shell_benchmarks.h"
#include "softshell/engine/solver.h"

namespace softshell::engine {
namespace {

constexpr double kYoung = 7.0e10;
constexpr double kThicknesses[] = {1e-2, 1e-3, 1e-4, 1e-5, 1e-6};  // t / L with L = 1

double limit_w(const ShellModel& model, const Eigen::VectorXd& u, const SurfacePoint& p) {
  LimitStencil st = model.evaluator().stencil(p);
  double w = 0.0;
  for (size_t k = 0; k < st.size(); ++k) w += st.position[k] * u[3 * st.indices[k] + 2];
  return w;
}

// A free square plate (a = 1, nu = 0.3, OpenSubdiv's boundary rule) held at three corners and
// loaded by a force P at the fourth: the reactions make it the pure-twist case (P, -P, P, -P at
// the corners), w = P x y / (2 D (1 - nu)) exactly (a bilinear field, in the spline space), so
// w(a, a) D / (P a^2) = 1 / (2 (1 - nu)).
TEST(ThinShells, TwistedFreePlateIsExactAtEveryThickness) {
  constexpr double kNu = 0.3, kP = 1.0;
  const double exact = 1.0 / (2.0 * (1.0 - kNu));
  std::printf("\nTwisted free plate (nu = 0.3): relative error of w(a,a) D / (P a^2) against 1/(2(1-nu))\n");
  std::printf("%8s", "faces");
  for (double t : kThicknesses) std::printf(" %11.0e", t);
  std::printf("\n");
  double worst = 0.0;
  for (int n : {1, 2, 4, 8, 12}) {
    const test::Plate plate = test::make_plate(n, 1.0);
    std::printf("%5dx%-3d", n, n);
    for (double t : kThicknesses) {
      auto model = ShellModel::build(plate.mesh, Material{kYoung, kNu, t, 0.0});
      ASSERT_TRUE(model.ok()) << model.error().message;
      Solver solver(*model, std::make_shared<FactorCache>());
      DeformationRequest request;
      for (auto [s, r] : {std::pair{0.0, 0.0}, std::pair{1.0, 0.0}, std::pair{0.0, 1.0}}) {
        request.limit_constraints.push_back({plate.at(s, r), Vec3::Zero(), {}, {}});
      }
      request.surface_forces.push_back({plate.at(1.0, 1.0), Vec3(0.0, 0.0, kP)});
      auto solution = solver.solve(request);
      EXPECT_TRUE(solution.ok()) << n << "x" << n << ", t = " << t << ": " << solution.error().message;
      if (!solution.ok()) {
        std::printf(" %11s", "refused");
        continue;
      }
      EXPECT_FALSE(solution->stats.fast_path_rejected) << n << "x" << n << ", t = " << t;  // the fast path is right
      const double d = kYoung * t * t * t / (12.0 * (1.0 - kNu * kNu));
      const double coefficient = limit_w(**model, solution->displacement, plate.at(1.0, 1.0)) * d / kP;
      const double error = std::abs(coefficient / exact - 1.0);
      std::printf(" %11.2e", error);
      worst = std::max(worst, error);
      EXPECT_LT(error, 1e-7) << n << "x" << n << ", t = " << t << ": " << coefficient << " instead of " << exact;
    }
    std::printf("\n");
  }
  std::printf("worst %.2e\n", worst);
}

// A cantilever strip L = 1 by b = 0.25 (nu = 0) with a ghost ring of faces (boundary "none"),
// clamped at x = 0 by limit constraints on the displacement and the cross-edge derivative
// (README: the exact clamp), loaded by a uniform line load of total P on the free end x = L
// (consistent: 3 Gauss points per face edge). With nu = 0 the plate is a beam: w = P x^2 (3L - x)
// / (6 E I), cubic in x and constant across, in the spline space; the tip deflection is
// P L^3 / (3 E I), I = b t^3 / 12.
TEST(ThinShells, GhostClampedCantileverIsExactAtEveryThickness) {
  constexpr double kLength = 1.0, kWidth = 0.25, kP = 1.0;
  std::printf("\nGhost-layer clamped cantilever (nu = 0): relative error of the tip deflection against P L^3 / 3EI\n");
  std::printf("%8s", "faces");
  for (double t : kThicknesses) std::printf(" %11.0e", t);
  std::printf("\n");
  double worst = 0.0;
  for (auto [nx, ny] : {std::pair{1, 1}, std::pair{2, 1}, std::pair{4, 1}, std::pair{8, 2}, std::pair{16, 4},
                        std::pair{32, 8}}) {
    const test::Plate strip = test::make_rectangle(nx, ny, kLength, kWidth, true);
    DeformationRequest request;
    for (int j = 0; j < ny; ++j) {
      for (double s : {0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0}) {
        if (j > 0 && s == 0.0) continue;  // shared with the previous face
        request.limit_constraints.push_back({strip.at(0.0, (j + s) / ny), Vec3::Zero(), Vec3::Zero(), {}});
      }
    }
    const double gauss[3][2] = {{0.5 - std::sqrt(0.15), 5.0 / 18.0}, {0.5, 8.0 / 18.0}, {0.5 + std::sqrt(0.15), 5.0 / 18.0}};
    for (int j = 0; j < ny; ++j) {
      for (const auto& [s, w] : gauss) {
        request.surface_forces.push_back({strip.at(1.0, (j + s) / ny), Vec3(0.0, 0.0, kP * w / ny)});
      }
    }
    std::printf("%5dx%-3d", nx, ny);
    for (double t : kThicknesses) {
      auto model = ShellModel::build(strip.mesh, Material{kYoung, 0.0, t, 0.0});
      ASSERT_TRUE(model.ok()) << model.error().message;
      Solver solver(*model, std::make_shared<FactorCache>());
      auto solution = solver.solve(request);
      EXPECT_TRUE(solution.ok()) << nx << "x" << ny << ", t = " << t << ": " << solution.error().message;
      if (!solution.ok()) {
        std::printf(" %11s", "refused");
        continue;
      }
      EXPECT_FALSE(solution->stats.fast_path_rejected) << nx << "x" << ny << ", t = " << t;  // the fast path is right
      const double exact = kP * std::pow(kLength, 3) / (3.0 * kYoung * kWidth * t * t * t / 12.0);
      double error = 0.0;
      for (double s : {0.0, 0.5, 1.0}) {  // the whole tip edge deflects alike
        const double tip = limit_w(**model, solution->displacement, strip.at(1.0, s));
        error = std::max(error, std::abs(tip / exact - 1.0));
      }
      std::printf(" %11.2e", error);
      worst = std::max(worst, error);
      EXPECT_LT(error, 1e-8) << nx << "x" << ny << ", t = " << t;
    }
    std::printf("\n");
  }
  std::printf("worst %.2e\n", worst);
}

}  // namespace
}  // namespace softshell::engine
