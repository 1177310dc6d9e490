#pragma once
// Simple shapes for the demo's pictures (hands, grab points, forces, boxes, the floor) as
// triangle meshes the renderer draws.

#include <array>
#include <cstdint>
#include <vector>

#include "render.h"
#include "softshell/control_mesh.h"

namespace softshell::demo {

/// A triangle mesh with per-vertex normals and colours.
struct TriMesh {
  std::vector<Vec3> vertices, normals;
  std::vector<std::array<int32_t, 3>> triangles;
  std::vector<Rgb> colours;
  void append(const TriMesh& other);
  /// For `Renderer::draw`.
  ShadedMesh shaded() const;
};

TriMesh sphere(const Vec3& centre, double radius, const Rgb& colour);
/// A cylinder from `a` to `b`.
TriMesh tube(const Vec3& a, const Vec3& b, double radius, const Rgb& colour);
/// An arrow from `tail` to `tip` (shaft and cone).
TriMesh arrow(const Vec3& tail, const Vec3& tip, double radius, const Rgb& colour);
/// A box with corners `corners` (8, corner i has bit 2 = +x, bit 1 = +y, bit 0 = +z of its frame).
TriMesh box(const std::array<Vec3, 8>& corners, const Rgb& colour);
/// A checkered square of half width `half` around `centre` in the plane normal to `up`.
TriMesh floor_tiles(const Vec3& centre, const Vec3& up, double half, int tiles);

}  // namespace softshell::demo
