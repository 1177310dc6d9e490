// Tessellation at levels 1-4 (limit positions and normals, triangles, quadtree paths) and the
// rate of limit-stencil and limit-position evaluations at random points, for every shipped mesh.
#include <cstdio>
#include <random>

#include "bench_support.h"
#include "softshell/tessellation.h"
#include "test_meshes.h"

using namespace softshell;

int main() {
  std::printf("softshell tessellation benchmark on %s\n\n", bench::machine().c_str());
  std::printf("| mesh | CVs | faces | L1 | L2 | L3 | L4 | L4 triangles | stencils/s | evaluations/s |\n");
  std::printf("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  for (const std::string& name : test::asset_mesh_names()) {
    ControlMesh mesh = test::load_asset_mesh(name);
    auto evaluator = LimitEvaluator::create(mesh).value();
    std::printf("| %s | %d | %d |", name.c_str(), mesh.num_vertices(), mesh.num_faces());
    size_t triangles = 0;
    for (int level = 1; level <= 4; ++level) {
      const auto t0 = bench::Clock::now();
      auto t = Tessellation::create(evaluator, level).value();
      std::printf(" %.1f ms |", bench::ms_since(t0));
      triangles = t.triangles().size();
    }
    std::printf(" %zu |", triangles);
    // Random points: full stencils (N and 5 derivatives) and plain position evaluations.
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> uni(0.0, 1.0);
    std::vector<SurfacePoint> points;
    for (int i = 0; i < 20000; ++i) {
      const auto f = static_cast<int32_t>(rng() % static_cast<unsigned>(mesh.num_faces()));
      points.push_back({f, static_cast<int32_t>(rng() % static_cast<unsigned>(evaluator.num_subfaces(f))), uni(rng), uni(rng)});
    }
    LimitStencil st;
    auto t0 = bench::Clock::now();
    double sink = 0.0;
    for (const auto& p : points) {
      evaluator.stencil(p, st);
      sink += st.position[0];
    }
    const double stencil_rate = points.size() / (bench::ms_since(t0) / 1000.0);
    t0 = bench::Clock::now();
    for (const auto& p : points) sink += evaluator.evaluate(p).position.x();
    const double eval_rate = points.size() / (bench::ms_since(t0) / 1000.0);
    std::printf(" %.2e | %.2e |\n", stencil_rate, eval_rate);
    if (sink == 12345.678) std::printf(" ");
    std::fflush(stdout);
  }
  return 0;
}
