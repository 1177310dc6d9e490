#include "test_meshes.h"

#include <algorithm>

#include "softshell/obj_io.h"

namespace softshell::test {

std::filesystem::path asset_path(const std::string& relative) {
  return std::filesystem::path(SOFTSHELL_ASSET_DIR) / relative;
}

std::vector<std::string> asset_mesh_names() {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(asset_path("meshes"))) {
    if (entry.path().extension() == ".obj") names.push_back(entry.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

ControlMesh load_asset_mesh(const std::string& name) {
  return read_obj(asset_path("meshes/" + name)).value();
}

std::vector<std::string> small_asset_mesh_names(int max_vertices) {
  std::vector<std::string> out;
  for (const auto& name : asset_mesh_names()) {
    if (load_asset_mesh(name).num_vertices() <= max_vertices) out.push_back(name);
  }
  return out;
}

ControlMesh make_grid(int nx, int ny, double sx, double sy, const std::function<double(double, double)>& height) {
  std::vector<Vec3> positions;
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) {
      const double x = sx * i / nx, y = sy * j / ny;
      positions.emplace_back(x, y, height ? height(x, y) : 0.0);
    }
  }
  std::vector<std::vector<int32_t>> faces;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      faces.push_back({grid_index(nx, i, j), grid_index(nx, i + 1, j), grid_index(nx, i + 1, j + 1),
                       grid_index(nx, i, j + 1)});
    }
  }
  return ControlMesh(std::move(positions), faces);
}

}  // namespace softshell::test
