// softshell-demo: loads a Catmull-Clark control mesh, tessellates its limit surface and writes it.
// (The push/pull session with the embedded server grows here as the layers land.)
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <string>

#include "softshell/limit_evaluator.h"
#include "softshell/mesh_validation.h"
#include "softshell/obj_io.h"
#include "softshell/tessellation.h"

namespace {

std::filesystem::path default_mesh() {
  for (const char* dir : {SOFTSHELL_ASSET_DIR, SOFTSHELL_INSTALLED_ASSET_DIR}) {
    std::filesystem::path p = std::filesystem::path(dir) / "meshes" / "spot_control_mesh.obj";
    if (std::filesystem::exists(p)) return p;
  }
  return "spot_control_mesh.obj";
}

void usage() {
  std::cout << "usage: softshell-demo [--mesh FILE.obj] [--level L] [--out DIR] [--quiet]\n"
               "  --mesh FILE   control mesh to load (default: the shipped spot_control_mesh.obj)\n"
               "  --level L     tessellation level of the limit surface, 0..6 (default 3)\n"
               "  --out DIR     where outputs go (default: demo-out)\n"
               "  --quiet       no progress on stderr\n";
}

}  // namespace

int main(int argc, char** argv) {
  std::filesystem::path mesh_path = default_mesh();
  std::filesystem::path out_dir = "demo-out";
  int level = 3;
  bool quiet = false;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "softshell-demo: " << arg << " needs a value\n";
        std::exit(2);
      }
      return argv[++i];
    };
    if (arg == "--mesh") mesh_path = value();
    else if (arg == "--out") out_dir = value();
    else if (arg == "--level") {
      try {
        level = std::stoi(value());
      } catch (const std::exception&) {
        std::cerr << "softshell-demo: --level needs an integer\n";
        return 2;
      }
    } else if (arg == "--quiet") quiet = true;
    else if (arg == "--help" || arg == "-h") {
      usage();
      return 0;
    } else {
      std::cerr << "softshell-demo: unknown option " << arg << "\n";
      usage();
      return 2;
    }
  }

  using Clock = std::chrono::steady_clock;
  auto mesh = softshell::read_obj(mesh_path);
  if (!mesh) {
    std::cerr << "softshell-demo: " << mesh.error().message << "\n";
    return 1;
  }
  auto t0 = Clock::now();
  auto evaluator = softshell::LimitEvaluator::create(*mesh);
  if (!evaluator) {
    std::cerr << "softshell-demo: " << mesh_path.string() << ": " << evaluator.error().message << "\n";
    return 1;
  }
  auto tessellation = softshell::Tessellation::create(*evaluator, level);
  if (!tessellation) {
    std::cerr << "softshell-demo: " << tessellation.error().message << "\n";
    return 1;
  }
  const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  std::error_code ec;
  std::filesystem::create_directories(out_dir, ec);
  const auto surface_path = out_dir / "limit_surface.obj";
  const auto cage_path = out_dir / "control_mesh.obj";
  if (auto ok = softshell::write_triangles_obj(surface_path, tessellation->vertices(), tessellation->triangles(),
                                               tessellation->normals());
      !ok) {
    std::cerr << "softshell-demo: " << ok.error().message << "\n";
    return 1;
  }
  if (auto ok = softshell::write_obj(*mesh, cage_path); !ok) {
    std::cerr << "softshell-demo: " << ok.error().message << "\n";
    return 1;
  }
  if (!quiet) std::cerr << "tessellated in " << ms << " ms\n";
  std::cout << "mesh:          " << mesh_path.string() << " (" << mesh->num_vertices() << " control points, "
            << mesh->num_faces() << " faces)\n"
            << "limit surface: level " << level << ", " << tessellation->triangles().size() << " triangles, "
            << "chordal error " << tessellation->chordal_error() << "\n"
            << "wrote:         " << surface_path.string() << ", " << cage_path.string() << "\n";
  return 0;
}
