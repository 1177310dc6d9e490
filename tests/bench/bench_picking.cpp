// bench_picking: ray picking against tessellations of ~10k to ~200k triangles.
//
// For each mesh and level: BVH build and refit time, then the time per ray of the BVH query alone
// (the target: <= 20 us for ~100k triangles) and of a whole pick (BVH + quadtree mapping +
// Newton refinement on the exact limit surface). Rays come from a sphere around the object and are
// aimed at random points of random triangles, so nearly all of them hit.
//
// Usage: bench_picking [rays per case, default 20000]

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "softshell/picking.h"
#include "test_meshes.h"

using namespace softshell;
using Clock = std::chrono::steady_clock;

namespace {

std::vector<Ray> aimed_rays(const Tessellation& t, int count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::normal_distribution<double> normal;
  Vec3 lo = t.vertices()[0], hi = lo;
  for (const Vec3& v : t.vertices()) {
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  const Vec3 centre = 0.5 * (lo + hi);
  const double size = (hi - lo).norm();
  std::vector<Ray> rays;
  rays.reserve(static_cast<size_t>(count));
  for (int i = 0; i < count; ++i) {
    const auto& tri = t.triangles()[rng() % t.triangles().size()];
    double a = uni(rng), b = uni(rng);
    if (a + b > 1.0) {
      a = 1.0 - a;
      b = 1.0 - b;
    }
    const Vec3 target = (1 - a - b) * t.vertices()[static_cast<size_t>(tri[0])] +
                        a * t.vertices()[static_cast<size_t>(tri[1])] + b * t.vertices()[static_cast<size_t>(tri[2])];
    const Vec3 dir = Vec3(normal(rng), normal(rng), normal(rng)).normalized();
    Ray ray;
    ray.origin = centre + 1.5 * size * dir;
    ray.direction = target - ray.origin;
    rays.push_back(ray);
  }
  return rays;
}

double us_since(Clock::time_point start) {
  return std::chrono::duration<double, std::micro>(Clock::now() - start).count();
}

}  // namespace

int main(int argc, char** argv) {
  const int rays_per_case = argc > 1 ? std::max(100, std::atoi(argv[1])) : 20000;
  struct Case {
    const char* mesh;
    int level;
  };
  const Case cases[] = {{"catmark_torus.obj", 4},        {"spot_control_mesh.obj", 3}, {"spot_quadrangulated.obj", 2},
                        {"blub_quadrangulated.obj", 1}, {"blub_quadrangulated.obj", 2}};
  std::printf("bench_picking: %d rays per case (aimed at random surface points from a sphere around the object)\n\n",
              rays_per_case);
  std::printf("| mesh | level | triangles | BVH build ms | refit ms | nodes | depth | BVH us/ray | pick us/ray | "
              "converged | Newton steps | hits |\n");
  std::printf("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  bool target_met = true;
  for (const Case& c : cases) {
    const ControlMesh mesh = test::load_asset_mesh(c.mesh);
    const LimitEvaluator ev = LimitEvaluator::create(mesh).value();
    Tessellation t = Tessellation::create(ev, c.level).value();
    Picker picker = Picker::create(t).value();
    const double build_ms = picker.bvh().stats().build_ms;
    // Refit after a (small) deformation.
    std::vector<Vec3> moved = mesh.positions();
    for (size_t i = 0; i < moved.size(); ++i) moved[i].z() += 1e-3 * static_cast<double>(i % 7);
    t.update(moved);
    picker.refit().value();
    const double refit_ms = picker.bvh().stats().refit_ms;
    t.update(mesh.positions());
    picker.refit().value();

    const std::vector<Ray> rays = aimed_rays(t, rays_per_case, 42);
    // BVH only.
    int hits = 0;
    auto start = Clock::now();
    for (const Ray& ray : rays) hits += picker.bvh().intersect(ray).has_value() ? 1 : 0;
    const double bvh_us = us_since(start) / static_cast<double>(rays.size());
    // Whole pick.
    int converged = 0;
    long steps = 0;
    start = Clock::now();
    for (const Ray& ray : rays) {
      const auto pick = picker.pick(ray).value();
      if (pick && pick->status == RefineStatus::kConverged) {
        ++converged;
        steps += pick->iterations;
      }
    }
    const double pick_us = us_since(start) / static_cast<double>(rays.size());
    const auto tris = static_cast<int64_t>(t.triangles().size());
    if (tris >= 80'000 && tris <= 150'000 && bvh_us > 20.0) target_met = false;
    std::printf("| %s | %d | %lld | %.1f | %.2f | %d | %d | %.2f | %.2f | %.1f%% | %.2f | %.1f%% |\n", c.mesh, c.level,
                static_cast<long long>(tris), build_ms, refit_ms, picker.bvh().stats().nodes,
                picker.bvh().stats().depth, bvh_us, pick_us, 100.0 * converged / std::max(hits, 1),
                converged ? static_cast<double>(steps) / converged : 0.0, 100.0 * hits / static_cast<double>(rays.size()));
  }
  std::printf("\ntarget (one ray, ~100k triangles, BVH built): <= 20 us: %s\n", target_met ? "met" : "MISSED");
  return target_met ? 0 : 1;
}
