// Precompute, factorization and solve times for every shipped mesh, beside the paper's Table 1.
//
// Each mesh is held by vertex constraints on three control points of every connected component
// (a statically determinate support) and then "grabbed": a limit constraint moves a surface point,
// a new point every solve, the supports stay. The first solve factorizes K with the supports
// eliminated; every later one reuses the cached factor (triangular solves + a small Schur system).
#include <cstdio>
#include <random>

#include "bench_support.h"
#include "softshell/engine/solver.h"
#include "softshell/limit_evaluator.h"
#include "test_meshes.h"

using namespace softshell;

namespace {

int count_evs(const ControlMesh& mesh) {
  std::vector<int> valence(static_cast<size_t>(mesh.num_vertices()), 0);
  std::map<std::pair<int, int>, int> edges;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    auto fv = mesh.face(f);
    for (size_t i = 0; i < fv.size(); ++i) {
      const int a = fv[i], b = fv[(i + 1) % fv.size()];
      ++edges[{std::min(a, b), std::max(a, b)}];
    }
  }
  std::vector<char> boundary(valence.size(), 0);
  for (const auto& [e, n] : edges) {
    ++valence[static_cast<size_t>(e.first)];
    ++valence[static_cast<size_t>(e.second)];
    if (n == 1) boundary[static_cast<size_t>(e.first)] = boundary[static_cast<size_t>(e.second)] = 1;
  }
  int evs = 0;
  for (size_t v = 0; v < valence.size(); ++v) evs += !boundary[v] && valence[v] != 4;
  return evs;
}

}  // namespace

int main(int argc, char** argv) {
  const int solves = argc > 1 ? std::atoi(argv[1]) : 20;
  std::printf("softshell engine benchmark on %s\n", bench::machine().c_str());
  std::printf("paper (Table 1, Intel i7-3820): Cactus 60 CVs 14 s / 2 ms, Barrel 210 CVs 7 s / 18 ms, "
              "Car door 218 CVs 20 s / 18 ms, Horse 472 CVs 82 s / 75 ms (precompute / solve)\n\n");
  std::printf("| mesh | CVs | EVs | faces | DOFs | precompute | first solve (factorize) | solve p50 | solve p95 | paper, nearest size |\n");
  std::printf("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |\n");
  const Material material{6.9e10, 0.33, 0.002, 2700.0};
  for (const std::string& name : test::asset_mesh_names()) {
    ControlMesh mesh = test::load_asset_mesh(name);
    // Meshes are in different units: scale to a 1 m bounding diagonal.
    const double scale = 1.0 / mesh.bounding_diagonal();
    for (Vec3& p : mesh.positions()) p *= scale;

    auto t0 = bench::Clock::now();
    auto model = engine::ShellModel::build(mesh, material);
    const double precompute = bench::ms_since(t0);
    if (!model.ok()) {
      std::printf("| %s | %s |\n", name.c_str(), model.error().message.c_str());
      continue;
    }
    // Supports: the control points of one face of every component (three points would leave
    // the zero-energy modes of tiny all-valence-3 parts free).
    DeformationRequest base;
    std::vector<char> held((*model)->num_components(), 0);
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      const int32_t c = (*model)->component_of()[static_cast<size_t>(mesh.face(f)[0])];
      if (held[static_cast<size_t>(c)]) continue;
      held[static_cast<size_t>(c)] = 1;
      for (int32_t v : mesh.face(f)) base.vertex_constraints.push_back({v, kAxisAll, Vec3::Zero()});
    }
    std::vector<int> size((*model)->num_components(), 0);
    for (int32_t c : (*model)->component_of()) ++size[static_cast<size_t>(c)];
    const int32_t largest = static_cast<int32_t>(std::max_element(size.begin(), size.end()) - size.begin());
    engine::Solver solver(*model, std::make_shared<engine::FactorCache>());
    std::mt19937 rng(1);
    std::vector<double> times;
    double first = 0.0;
    for (int i = 0; i <= solves; ++i) {
      DeformationRequest request = base;
      // A face of the largest component, away from the supports.
      int32_t face = static_cast<int32_t>(rng() % static_cast<unsigned>(mesh.num_faces()));
      while ((*model)->component_of()[static_cast<size_t>(mesh.face(face)[0])] != largest) face = (face + 1) % mesh.num_faces();
      request.limit_constraints.push_back({{face, 0, 0.5, 0.5}, Vec3(0.0, 0.0, 0.01), {}, {}});
      t0 = bench::Clock::now();
      auto solution = solver.solve(request);
      const double ms = bench::ms_since(t0);
      if (!solution.ok()) {
        std::fprintf(stderr, "%s: %s\n", name.c_str(), solution.error().message.c_str());
        break;
      }
      if (i == 0) first = ms; else times.push_back(ms);
    }
    const int n = mesh.num_vertices();
    const char* paper = n < 135 ? "Cactus (60): 14 s / 2 ms" : n < 345 ? "Barrel (210) / Car door (218): 7-20 s / 18 ms"
                                                                       : "Horse (472): 82 s / 75 ms";
    std::printf("| %s | %d | %d | %d | %d | %.0f ms | %.1f ms | %.2f ms | %.2f ms | %s |\n", name.c_str(), n,
                count_evs(mesh), mesh.num_faces(), 3 * n, precompute, first, bench::percentile(times, 0.5),
                bench::percentile(times, 0.95), paper);
    std::fflush(stdout);
  }
  return 0;
}
