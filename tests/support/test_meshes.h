#pragma once
// Shared test corpus: the shipped meshes (assets/meshes) and generated grids.

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "softshell/control_mesh.h"

namespace softshell::test {

/// Absolute path of a file under assets/.
std::filesystem::path asset_path(const std::string& relative);

/// Names (file names without directory) of every .obj under assets/meshes, sorted.
std::vector<std::string> asset_mesh_names();

/// Loads assets/meshes/<name>; fails the test (throws) if it cannot.
ControlMesh load_asset_mesh(const std::string& name);

/// Small meshes (at most `max_vertices` control points) from assets, for the slower tests.
std::vector<std::string> small_asset_mesh_names(int max_vertices);

/// A regular grid of nx x ny quads over [0, sx] x [0, sy] in the z = height(x, y) surface;
/// (nx + 1) x (ny + 1) control points, row-major in x, counter-clockwise seen from +z.
ControlMesh make_grid(int nx, int ny, double sx = 1.0, double sy = 1.0,
                      const std::function<double(double, double)>& height = nullptr);

/// Index of control point (i, j) of make_grid(nx, ...).
inline int grid_index(int nx, int i, int j) { return j * (nx + 1) + i; }

}  // namespace softshell::test
