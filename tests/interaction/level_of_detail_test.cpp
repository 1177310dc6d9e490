#include "softshell/level_of_detail.h"

#include <deque>
#include <map>
#include <random>

#include <gtest/gtest.h>

#include "scripted_session.h"
#include "test_meshes.h"

namespace softshell {
namespace {

std::vector<std::string> lod_meshes() {
  return {"catmark_torus.obj", "catmark_nonquads.obj", "catmark_helmet.obj", "catmark_tent.obj",
          "catmark_cube.obj",  "catmark_gregory_test5.obj"};
}

SurfacePoint random_point(const LimitEvaluator& ev, std::mt19937& rng) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  SurfacePoint p;
  do {
    p.face = static_cast<int32_t>(rng() % static_cast<uint32_t>(ev.num_faces()));
  } while (!ev.has_limit_surface(p.face));
  p.subface = static_cast<int32_t>(rng() % static_cast<uint32_t>(ev.num_subfaces(p.face)));
  p.u = uni(rng);
  p.v = uni(rng);
  // Edges and corners too.
  if (rng() % 8 == 0) p.u = (rng() % 2) ? 1.0 : 0.0;
  if (rng() % 8 == 0) p.v = 0.5;
  return p;
}

// The coarse and the refined control mesh have the same limit surface: positions and tangents
// (mapped by the chain rule) agree to rounding when the evaluators approximate irregular faces
// over the same regions.
TEST(LevelOfDetail, SameLimitSurfaceOnBothLevels) {
  std::mt19937 rng(1);
  // Both the smooth surface (tags ignored, the default) and the tagged one (sharp_features).
  for (const bool sharp : {false, true}) {
  for (const std::string& name : lod_meshes()) {
    const ControlMesh coarse = test::load_asset_mesh(name);
    const double size = coarse.bounding_diagonal();
    LimitEvaluator::Options coarse_options{4, 6};
    coarse_options.sharp_features = sharp;
    const auto ev = LimitEvaluator::create(coarse, coarse_options).value();
    for (int levels = 1; levels <= 2; ++levels) {
      const auto r = MeshRefinement::create(coarse, levels, 20'000'000, sharp).value();
      EXPECT_TRUE(r.fine().all_quads());
      EXPECT_EQ(r.fine().has_sharpness(), sharp && coarse.has_sharpness()) << name;
      const auto fine_ev = LimitEvaluator::create(r.fine(), r.fine_evaluator_options(coarse_options)).value();
      for (int i = 0; i < 300; ++i) {
        const SurfacePoint p = random_point(ev, rng);
        const SurfacePoint q = r.fine_point(p).value();
        ASSERT_TRUE(fine_ev.check(q).ok());
        const LimitSample a = ev.evaluate(p), b = fine_ev.evaluate(q);
        ASSERT_LT((a.position - b.position).norm(), 1e-12 * size)
            << name << " levels " << levels << " face " << p.face << "/" << p.subface << " (" << p.u << ", " << p.v << ")";
        // Tangents through the limit constraint transfer (derivatives w.r.t. each level's own u, v).
        LimitConstraint lc{p, Vec3::Zero(), a.du, a.dv};
        const LimitConstraint fl = r.limit_constraint_to_fine(lc).value();
        EXPECT_EQ(fl.point, q);
        ASSERT_TRUE(fl.du_displacement && fl.dv_displacement);
        EXPECT_LT((*fl.du_displacement - b.du).norm(), 1e-9 * a.du.norm()) << name;
        EXPECT_LT((*fl.dv_displacement - b.dv).norm(), 1e-9 * a.dv.norm()) << name;
        // And back.
        const SurfacePoint back = r.coarse_point(q).value();
        EXPECT_EQ(back.face, p.face);
        EXPECT_EQ(back.subface, p.subface);
        EXPECT_NEAR(back.u, p.u, 1e-15);
        EXPECT_NEAR(back.v, p.v, 1e-15);
      }
    }
  }
}
}

// With the default evaluator options on both levels the surfaces still agree exactly on regular
// faces (bicubic B-spline patches, refinement is exact) and closely next to extraordinary vertices.
TEST(LevelOfDetail, DefaultOptionsAgreeExactlyOnRegularFaces) {
  std::mt19937 rng(4);
  const ControlMesh coarse = test::load_asset_mesh("spot_control_mesh.obj");
  const double size = coarse.bounding_diagonal();
  const auto ev = LimitEvaluator::create(coarse).value();
  const auto r = MeshRefinement::create(coarse, 1).value();
  const auto fine_ev = LimitEvaluator::create(r.fine()).value();
  double worst_irregular = 0.0;
  int regular = 0;
  for (int i = 0; i < 500; ++i) {
    const SurfacePoint p = random_point(ev, rng);
    const double d = (ev.evaluate(p).position - fine_ev.evaluate(r.fine_point(p).value()).position).norm();
    if (ev.is_regular(p.face)) {
      ++regular;
      EXPECT_LT(d, 1e-12 * size);
    } else {
      worst_irregular = std::max(worst_irregular, d);
    }
  }
  EXPECT_GT(regular, 20);
  EXPECT_LT(worst_irregular, 1e-2 * size);
}

// "Coarse control point i is fine control point i": the limit point of coarse vertex i (evaluated at
// a face corner) is the limit point of fine vertex i, and S's row i is the vertex rule around i.
TEST(LevelOfDetail, CoarseControlPointIIsFineControlPointI) {
  for (const std::string& name : lod_meshes()) {
    const ControlMesh coarse = test::load_asset_mesh(name);
    const double size = coarse.bounding_diagonal();
    const LimitEvaluator::Options options{4, 6};
    const auto ev = LimitEvaluator::create(coarse, options).value();
    for (int levels = 1; levels <= 3; ++levels) {
      const auto r = MeshRefinement::create(coarse, levels).value();
      const auto fine_ev = LimitEvaluator::create(r.fine(), r.fine_evaluator_options(options)).value();
      ASSERT_GT(r.fine().num_vertices(), coarse.num_vertices());
      // For every coarse vertex: one coarse face corner and one fine face corner at that vertex.
      auto corner_point = [](const ControlMesh& mesh, int32_t vertex) -> std::optional<SurfacePoint> {
        for (int32_t f = 0; f < mesh.num_faces(); ++f) {
          const auto fv = mesh.face(f);
          for (size_t c = 0; c < fv.size(); ++c) {
            if (fv[c] != vertex) continue;
            if (fv.size() == 4) {
              static constexpr double uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
              return SurfacePoint{f, 0, uv[c][0], uv[c][1]};
            }
            return SurfacePoint{f, static_cast<int32_t>(c), 0.0, 0.0};
          }
        }
        return std::nullopt;
      };
      for (int32_t i = 0; i < coarse.num_vertices(); ++i) {
        const auto pc = corner_point(coarse, i), pf = corner_point(r.fine(), i);
        ASSERT_TRUE(pc && pf);
        EXPECT_LT((ev.evaluate(*pc).position - fine_ev.evaluate(*pf).position).norm(), 1e-12 * size)
            << name << " vertex " << i << " levels " << levels;
      }
      // Rows of S sum to 1; the row of a vertex child is centred on that vertex.
      const auto& S = r.matrix();
      ASSERT_EQ(S.rows(), r.fine().num_vertices());
      ASSERT_EQ(S.cols(), coarse.num_vertices());
      for (Eigen::Index row = 0; row < S.rows(); ++row) EXPECT_NEAR(S.row(row).sum(), 1.0, 1e-12);
      for (int32_t i = 0; i < coarse.num_vertices(); ++i) {
        Eigen::Index arg_max = -1;
        double max_weight = -1.0;
        for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(S, i); it; ++it) {
          if (it.value() > max_weight) {
            max_weight = it.value();
            arg_max = it.col();
          }
        }
        EXPECT_EQ(arg_max, i) << name;
      }
      // x_f = S x_c, for deformed coarse shapes too.
      std::vector<Vec3> moved = coarse.positions();
      for (size_t k = 0; k < moved.size(); ++k) moved[k] += Vec3(0.01 * k, 0.0, -0.02 * (k % 3));
      const auto fine_moved = r.refine_positions(moved).value();
      for (int j = 0; j < 20; ++j) {
        const SurfacePoint p{static_cast<int32_t>(j % coarse.num_faces()), 0, 0.3, 0.6};
        const SurfacePoint q = r.fine_point(p).value();
        EXPECT_LT((ev.evaluate(p, moved).position - fine_ev.evaluate(q, fine_moved).position).norm(), 1e-11 * (size + 10.0));
      }
    }
  }
}

TEST(LevelOfDetail, ForcesKeepTheTotalExactly) {
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  for (const std::string& name : {std::string("catmark_nonquads.obj"), std::string("catmark_torus.obj")}) {
    const ControlMesh coarse = test::load_asset_mesh(name);
    const auto r = MeshRefinement::create(coarse, 2).value();
    std::vector<PointForce> fc;
    for (int i = 0; i < 5; ++i) {
      fc.push_back({static_cast<int32_t>(rng() % static_cast<uint32_t>(coarse.num_vertices())),
                    Vec3(normal(rng), normal(rng), normal(rng)) * 10.0});
    }
    fc.push_back({fc[0].index, Vec3(1, 2, 3)});  // repeated indices add up
    Vec3 total = Vec3::Zero();
    for (const auto& f : fc) total += f.force;
    // Random coarse displacement, and its fine counterpart S u_c.
    std::vector<Vec3> uc(static_cast<size_t>(coarse.num_vertices()));
    for (Vec3& u : uc) u = Vec3(normal(rng), normal(rng), normal(rng));
    const std::vector<Vec3> uf = r.refine_positions(uc).value();
    double work_c = 0.0;
    for (const auto& f : fc) work_c += f.force.dot(uc[static_cast<size_t>(f.index)]);

    for (ForceTransfer transfer : {ForceTransfer::kSubdivide, ForceTransfer::kVirtualWork}) {
      const auto ff = r.forces_to_fine(fc, transfer).value();
      Vec3 fine_total = Vec3::Zero();
      double work_f = 0.0;
      for (const auto& f : ff) {
        fine_total += f.force;
        work_f += f.force.dot(uf[static_cast<size_t>(f.index)]);
      }
      EXPECT_LT((fine_total - total).norm(), 1e-12 * total.norm()) << name;
      if (transfer == ForceTransfer::kVirtualWork) {
        // Sᵀ f_f = f_c exactly, hence the virtual work of every coarse displacement.
        EXPECT_NEAR(work_f, work_c, 1e-9 * std::abs(work_c) + 1e-9);
        const auto back = r.forces_to_coarse(ff).value();
        std::map<int32_t, Vec3> expected;
        for (const auto& f : fc) expected.try_emplace(f.index, Vec3::Zero()).first->second += f.force;
        for (const auto& f : back) {
          const Vec3 e = expected.count(f.index) ? expected[f.index] : Vec3::Zero();
          EXPECT_LT((f.force - e).norm(), 1e-9 * total.norm()) << name << " index " << f.index;
        }
      } else {
        // Local: every fine force lies in the support of a loaded coarse point.
        const auto& S = r.matrix();
        for (const auto& f : ff) {
          bool in_support = false;
          for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(S, f.index); it; ++it) {
            for (const auto& c : fc) in_support |= it.col() == c.index;
          }
          EXPECT_TRUE(in_support);
        }
        EXPECT_LT(ff.size(), static_cast<size_t>(r.fine().num_vertices()));
      }
    }
    // Fine to coarse: Sᵀ f_f keeps the total and the virtual work exactly.
    std::vector<PointForce> ff;
    for (int i = 0; i < 8; ++i) {
      ff.push_back({static_cast<int32_t>(rng() % static_cast<uint32_t>(r.fine().num_vertices())),
                    Vec3(normal(rng), normal(rng), normal(rng))});
    }
    Vec3 fine_total = Vec3::Zero();
    double work_f = 0.0;
    for (const auto& f : ff) {
      fine_total += f.force;
      work_f += f.force.dot(uf[static_cast<size_t>(f.index)]);
    }
    const auto back = r.forces_to_coarse(ff).value();
    Vec3 coarse_total = Vec3::Zero();
    double work_back = 0.0;
    for (const auto& f : back) {
      coarse_total += f.force;
      work_back += f.force.dot(uc[static_cast<size_t>(f.index)]);
    }
    EXPECT_LT((coarse_total - fine_total).norm(), 1e-12 * fine_total.norm());
    EXPECT_NEAR(work_back, work_f, 1e-10 * std::abs(work_f) + 1e-12);
  }
}

TEST(LevelOfDetail, RequestTransfer) {
  const ControlMesh coarse = test::load_asset_mesh("catmark_nonquads.obj");
  const auto r = MeshRefinement::create(coarse, 1).value();
  DeformationRequest req;
  req.vertex_constraints = {{0, kAxisAll, Vec3::Zero()}, {5, kAxisY, Vec3(0, 0.1, 0)}};
  req.lagrange_constraints = {{{1, 2}, {Vec3(1, 1, 1), Vec3(-1, -1, -1)}, Vec3::Zero()}};
  req.forces = {{3, Vec3(0, -1, 0)}};
  req.limit_constraints = {{{2, 1, 0.25, 0.75}, Vec3(0, 0, 0.05), std::nullopt, std::nullopt}};
  req.surface_forces = {{{0, 0, 0.5, 0.5}, Vec3(1, 0, 0)}};
  req.surface_load = Vec3(0, 0, -9.81);
  req.pressure = 2.0;
  const DeformationRequest fine = r.request_to_fine(req).value();
  ASSERT_EQ(fine.vertex_constraints.size(), 2u);
  EXPECT_EQ(fine.vertex_constraints[1].index, 5);
  EXPECT_EQ(fine.vertex_constraints[1].mask, static_cast<uint32_t>(kAxisY));
  ASSERT_EQ(fine.limit_constraints.size(), 1u);
  EXPECT_EQ(fine.limit_constraints[0].point, r.fine_point(req.limit_constraints[0].point).value());
  EXPECT_FALSE(fine.limit_constraints[0].du_displacement.has_value());
  EXPECT_EQ(fine.surface_forces[0].point, r.fine_point(req.surface_forces[0].point).value());
  EXPECT_EQ(fine.surface_load, req.surface_load);
  EXPECT_EQ(fine.pressure, 2.0);
  EXPECT_EQ(fine.lagrange_constraints.size(), 1u);
  Vec3 total = Vec3::Zero();
  for (const auto& f : fine.forces) total += f.force;
  EXPECT_LT((total - Vec3(0, -1, 0)).norm(), 1e-14);

  // Bad input is an error with a reason.
  DeformationRequest bad = req;
  bad.vertex_constraints[0].index = 999;
  EXPECT_EQ(r.request_to_fine(bad).error().code, ErrorCode::kInvalidArgument);
  bad = req;
  bad.forces[0].force.x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(r.request_to_fine(bad).error().code, ErrorCode::kInvalidArgument);
  bad = req;
  bad.limit_constraints[0].point.subface = 9;
  EXPECT_EQ(r.request_to_fine(bad).error().code, ErrorCode::kInvalidArgument);
  bad = req;
  bad.vertex_constraints[0].mask = 0;
  EXPECT_EQ(r.request_to_fine(bad).error().code, ErrorCode::kInvalidArgument);
  EXPECT_FALSE(r.fine_point({0, 0, 1.5, 0.5}).ok());
  EXPECT_FALSE(r.coarse_point({-1, 0, 0.5, 0.5}).ok());
  EXPECT_FALSE(r.forces_to_coarse({{r.fine().num_vertices(), Vec3::Zero()}}).ok());
  EXPECT_FALSE(r.refine_positions({}).ok());
}

TEST(LevelOfDetail, RejectsBadLevelsAndMeshes) {
  const ControlMesh coarse = test::load_asset_mesh("catmark_cube.obj");
  EXPECT_EQ(MeshRefinement::create(coarse, 0).error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(MeshRefinement::create(coarse, 7).error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(MeshRefinement::create(coarse, 3, 100).error().code, ErrorCode::kResourceExhausted);
  ControlMesh broken({Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY()}, std::vector<std::vector<int32_t>>{{0, 1, 7}});
  EXPECT_FALSE(MeshRefinement::create(broken, 1).ok());
}

TEST(LevelOfDetail, CreasesAndBoundaryModeAreCarried) {
  ControlMesh coarse = test::load_asset_mesh("catmark_helmet.obj");
  ASSERT_TRUE(coarse.has_sharpness());
  EXPECT_FALSE(MeshRefinement::create(coarse, 1).value().fine().has_sharpness());  // default: smooth surface
  const auto r = MeshRefinement::create(coarse, 1, 20'000'000, /*sharp_features=*/true).value();
  EXPECT_FALSE(r.fine().creases().empty());
  // Semi-sharp creases lose one unit of sharpness a level: the fine edge from coarse vertex v0
  // towards v1 (v0 is fine vertex v0) carries sharpness s - 1.
  for (const Crease& c : coarse.creases()) {
    const Vec3 towards = coarse.positions()[static_cast<size_t>(c.v1)] - coarse.positions()[static_cast<size_t>(c.v0)];
    bool found = false;
    for (const Crease& f : r.fine().creases()) {
      const int32_t other = f.v0 == c.v0 ? f.v1 : (f.v1 == c.v0 ? f.v0 : -1);
      if (other < 0) continue;
      const Vec3 along = r.fine().positions()[static_cast<size_t>(other)] - r.fine().positions()[static_cast<size_t>(c.v0)];
      if (along.normalized().dot(towards.normalized()) < 0.9) continue;
      EXPECT_FLOAT_EQ(f.sharpness, c.sharpness >= 10.0f ? 10.0f : c.sharpness - 1.0f);
      found = true;
    }
    EXPECT_TRUE(found) << "crease " << c.v0 << "-" << c.v1;
  }

  ControlMesh grid = test::make_grid(4, 4);
  grid.set_boundary(BoundaryMode::kNone);
  const auto rg = MeshRefinement::create(grid, 1).value();
  EXPECT_EQ(rg.fine().boundary(), BoundaryMode::kNone);
  const auto ev = LimitEvaluator::create(grid, {4, 6}).value();
  const auto fev = LimitEvaluator::create(rg.fine(), rg.fine_evaluator_options({4, 6})).value();
  const SurfacePoint p{6, 0, 0.3, 0.9};  // an interior face of the 4x4 grid
  ASSERT_TRUE(ev.has_limit_surface(p.face));
  EXPECT_LT((ev.evaluate(p).position - fev.evaluate(rg.fine_point(p).value()).position).norm(), 1e-12);
}

// ------------------------------------------------------------------------------------------------
// ParallelLevels against a test double of Session whose results the test releases one by one.

using test::ScriptedSession;

TEST(ParallelLevels, CoarseFirstFineWhenReadyNeverStale) {
  ScriptedSession session;
  const ControlMesh coarse = test::make_grid(3, 3);
  auto levels = ParallelLevels::create(session, coarse, Material{}, 2).value();
  EXPECT_NE(levels->coarse_id(), levels->fine_id());
  const int32_t nc = coarse.num_vertices(), nf = levels->refinement().fine().num_vertices();

  DeformationRequest req;
  req.vertex_constraints = {{0, kAxisAll, Vec3::Zero()}};
  req.limit_constraints = {{{4, 0, 0.5, 0.5}, Vec3(0, 0, 0.1), std::nullopt, std::nullopt}};
  EXPECT_EQ(levels->submit(req).value(), 1u);
  ASSERT_EQ(session.calls(), 2u);
  // The fine request is the transferred one.
  EXPECT_EQ(session.request(1).limit_constraints[0].point,
            levels->refinement().fine_point(req.limit_constraints[0].point).value());
  EXPECT_FALSE(levels->poll().has_value());
  EXPECT_FALSE(levels->wait(std::chrono::milliseconds(5)).has_value());
  EXPECT_EQ(levels->in_flight(), 2u);

  // Coarse first, then fine.
  session.finish(0);
  auto a = levels->poll();
  ASSERT_TRUE(a.has_value());
  EXPECT_FALSE(a->fine);
  EXPECT_EQ(a->submission, 1u);
  EXPECT_EQ(a->result.value().positions.size(), static_cast<size_t>(nc));
  session.finish(1);
  auto b = levels->wait(std::chrono::milliseconds(1000));
  ASSERT_TRUE(b.has_value());
  EXPECT_TRUE(b->fine);
  EXPECT_EQ(b->result.value().positions.size(), static_cast<size_t>(nf));
  EXPECT_EQ(levels->in_flight(), 0u);

  // Two interactions: the second's coarse result supersedes the first's late fine result.
  EXPECT_EQ(levels->submit(req).value(), 2u);
  EXPECT_EQ(levels->submit(req).value(), 3u);
  session.finish(4);  // submission 3, coarse
  session.finish(3);  // submission 2, fine (older)
  auto c = levels->poll();
  ASSERT_TRUE(c.has_value());
  EXPECT_EQ(c->submission, 3u);
  EXPECT_FALSE(c->fine);
  EXPECT_FALSE(levels->poll().has_value());  // the stale fine result of 2 is never delivered
  session.finish(2);                          // submission 2, coarse: stale too
  EXPECT_FALSE(levels->poll().has_value());
  session.finish(5, false);  // submission 3, fine: an error is delivered as such
  auto d = levels->poll();
  ASSERT_TRUE(d.has_value());
  EXPECT_TRUE(d->fine);
  EXPECT_EQ(d->result.error().code, ErrorCode::kUnprocessable);
  EXPECT_EQ(levels->in_flight(), 0u);

  // A fine result that arrives before its coarse one is delivered, and the coarse one dropped.
  EXPECT_EQ(levels->submit(req).value(), 4u);
  session.finish(7);
  auto e = levels->poll();
  ASSERT_TRUE(e.has_value());
  EXPECT_TRUE(e->fine);
  session.finish(6);
  EXPECT_FALSE(levels->poll().has_value());

  // A request that does not fit the coarse mesh is refused before anything is sent.
  DeformationRequest bad;
  bad.forces = {{nc, Vec3::UnitX()}};
  const size_t calls = session.calls();
  EXPECT_EQ(levels->submit(bad).error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(session.calls(), calls);
}

}  // namespace
}  // namespace softshell
