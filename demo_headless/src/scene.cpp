#include "scene.h"

#include <cmath>

namespace softshell::demo {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Two unit vectors completing `axis` (unit) to an orthonormal frame.
std::array<Vec3, 2> frame_around(const Vec3& axis) {
  const Vec3 helper = std::abs(axis.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
  const Vec3 s = axis.cross(helper).normalized();
  return {s, axis.cross(s)};
}

// A ring-swept surface: radii[k] at heights[k] along the axis from `base`, 24 segments.
TriMesh lathe(const Vec3& base, const Vec3& axis, const std::vector<double>& heights, const std::vector<double>& radii,
              const Rgb& colour) {
  constexpr int kSegments = 24;
  TriMesh m;
  const auto [s, t] = frame_around(axis);
  for (size_t k = 0; k < heights.size(); ++k) {
    // The normal of a cone segment tilts by the radius change along the axis.
    const size_t k0 = k == 0 ? 0 : k - 1, k1 = k + 1 < heights.size() ? k + 1 : k;
    const double slope = heights[k1] == heights[k0] ? 0.0 : -(radii[k1] - radii[k0]) / (heights[k1] - heights[k0]);
    for (int j = 0; j < kSegments; ++j) {
      const double a = 2.0 * kPi * j / kSegments;
      const Vec3 radial = std::cos(a) * s + std::sin(a) * t;
      m.vertices.push_back(base + heights[k] * axis + radii[k] * radial);
      m.normals.push_back((radial + slope * axis).normalized());
      m.colours.push_back(colour);
    }
  }
  for (size_t k = 0; k + 1 < heights.size(); ++k) {
    for (int j = 0; j < kSegments; ++j) {
      const auto i0 = static_cast<int32_t>(k * kSegments + static_cast<size_t>(j));
      const auto i1 = static_cast<int32_t>(k * kSegments + static_cast<size_t>((j + 1) % kSegments));
      m.triangles.push_back({i0, i1, i1 + kSegments});
      m.triangles.push_back({i0, i1 + kSegments, i0 + kSegments});
    }
  }
  return m;
}

}  // namespace

void TriMesh::append(const TriMesh& other) {
  const auto base = static_cast<int32_t>(vertices.size());
  vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
  normals.insert(normals.end(), other.normals.begin(), other.normals.end());
  colours.insert(colours.end(), other.colours.begin(), other.colours.end());
  for (const auto& t : other.triangles) triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
}

ShadedMesh TriMesh::shaded() const {
  ShadedMesh s;
  s.vertices = &vertices;
  s.normals = &normals;
  s.triangles = &triangles;
  s.colours = &colours;
  return s;
}

TriMesh sphere(const Vec3& centre, double radius, const Rgb& colour) {
  std::vector<double> heights, radii;
  for (int k = 0; k <= 12; ++k) {
    const double a = kPi * k / 12.0;
    heights.push_back(-radius * std::cos(a));
    radii.push_back(radius * std::sin(a));
  }
  TriMesh m = lathe(centre, Vec3::UnitZ(), heights, radii, colour);
  for (size_t i = 0; i < m.vertices.size(); ++i) m.normals[i] = (m.vertices[i] - centre).normalized();
  return m;
}

TriMesh tube(const Vec3& a, const Vec3& b, double radius, const Rgb& colour) {
  const double length = (b - a).norm();
  if (!(length > 0.0)) return {};
  return lathe(a, (b - a) / length, {0.0, length}, {radius, radius}, colour);
}

TriMesh arrow(const Vec3& tail, const Vec3& tip, double radius, const Rgb& colour) {
  const double length = (tip - tail).norm();
  if (!(length > 0.0)) return {};
  const double head = std::min(0.4 * length, 5.0 * radius);
  const double shaft = length - head;
  return lathe(tail, (tip - tail) / length, {0.0, shaft, shaft, length}, {radius, radius, 2.5 * radius, 0.0}, colour);
}

TriMesh box(const std::array<Vec3, 8>& corner, const Rgb& colour) {
  static const int kFaces[6][4] = {{0, 1, 3, 2}, {4, 6, 7, 5}, {0, 4, 5, 1}, {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 5, 7, 3}};
  TriMesh m;
  for (const auto& face : kFaces) {
    const Vec3 n = (corner[face[1]] - corner[face[0]]).cross(corner[face[2]] - corner[face[0]]).normalized();
    const auto base = static_cast<int32_t>(m.vertices.size());
    for (int k = 0; k < 4; ++k) {
      m.vertices.push_back(corner[face[k]]);
      m.normals.push_back(n);
      m.colours.push_back(colour);
    }
    m.triangles.push_back({base, base + 1, base + 2});
    m.triangles.push_back({base, base + 2, base + 3});
  }
  return m;
}

TriMesh floor_tiles(const Vec3& centre, const Vec3& up, double half, int tiles) {
  const auto [s, t] = frame_around(up.normalized());
  TriMesh m;
  const double step = 2.0 * half / tiles;
  for (int i = 0; i < tiles; ++i) {
    for (int j = 0; j < tiles; ++j) {
      const Rgb colour = (i + j) % 2 ? Rgb{214, 210, 200} : Rgb{226, 222, 212};
      const Vec3 corner = centre + (-half + i * step) * s + (-half + j * step) * t;
      const auto base = static_cast<int32_t>(m.vertices.size());
      for (const auto& [di, dj] : {std::pair{0, 0}, std::pair{1, 0}, std::pair{1, 1}, std::pair{0, 1}}) {
        m.vertices.push_back(corner + di * step * s + dj * step * t);
        m.normals.push_back(up.normalized());
        m.colours.push_back(colour);
      }
      m.triangles.push_back({base, base + 1, base + 2});
      m.triangles.push_back({base, base + 2, base + 3});
    }
  }
  return m;
}

}  // namespace softshell::demo
