#pragma once
// A small headless software rasterizer for the demo's pictures: z-buffered triangles with
// per-vertex normals and a scalar field mapped through a colour map, a colour bar with labels,
// 2x supersampling, PNG output (stb_image_write).

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/result.h"

namespace softshell::demo {

/// An RGB image, 8 bits per channel, rows top to bottom.
struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;
  Image(int w, int h);
  void set(int x, int y, const std::array<uint8_t, 3>& c);
  Result<void> write_png(const std::filesystem::path& path) const;
};

/// A perspective camera.
struct Camera {
  Vec3 eye = Vec3(0, 0, 5), target = Vec3::Zero(), up = Vec3(0, 1, 0);
  double fov_deg = 35.0;
  /// Looks at a bounding box from direction `from` (eye - target), far enough to see all of it.
  static Camera framing(const Vec3& box_min, const Vec3& box_max, const Vec3& from, const Vec3& up);
};

/// Maps t in [0, 1] to a perceptually uniform colour (viridis).
std::array<uint8_t, 3> viridis(double t);

/// A triangle mesh with a scalar per vertex, as drawn.
struct ShadedMesh {
  const std::vector<Vec3>* vertices = nullptr;
  const std::vector<Vec3>* normals = nullptr;
  const std::vector<std::array<int32_t, 3>>* triangles = nullptr;
  const std::vector<double>* scalar = nullptr;  ///< per vertex; null = uniform grey
  double scalar_min = 0.0, scalar_max = 1.0;
};

/// Draws meshes into an image of the given size (supersampled internally).
class Renderer {
 public:
  Renderer(int width, int height, const Camera& camera);
  void draw(const ShadedMesh& mesh);
  /// Draws a vertical colour bar at the right edge with a title and min / max labels.
  void colour_bar(const std::string& title, double min, double max, const std::string& unit);
  /// Text at pixel (x, y) of the final image (top-left origin).
  void text(int x, int y, const std::string& s, const std::array<uint8_t, 3>& colour, int scale = 2);
  /// The final (downsampled) image.
  Image image() const;

 private:
  void fill_rect(double x0, double y0, double x1, double y1, const std::array<uint8_t, 3>& c);
  int w_, h_, ss_ = 2;
  Camera camera_;
  Eigen::Matrix4d view_proj_;
  std::vector<float> depth_;
  std::vector<std::array<float, 3>> colour_;
};

}  // namespace softshell::demo
