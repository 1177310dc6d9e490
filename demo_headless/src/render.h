#pragma once
// A small headless software rasterizer for the demo's pictures: z-buffered triangles with
// per-vertex normals, coloured by a scalar field (viridis), per-vertex colours or one colour,
// translucent "ghosts" drawn only where they lie in front, text and labels, 2x supersampling,
// PNG output (stb_image_write).

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/result.h"

namespace softshell::demo {

using Rgb = std::array<uint8_t, 3>;

/// An RGB image, 8 bits per channel, rows top to bottom.
struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;
  Image(int w, int h);
  void set(int x, int y, const Rgb& c);
  Rgb at(int x, int y) const;
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
Rgb viridis(double t);

/// A triangle mesh as drawn. Colour: `scalar` through viridis if given, else `colours` per
/// vertex if given, else `colour`.
struct ShadedMesh {
  const std::vector<Vec3>* vertices = nullptr;
  const std::vector<Vec3>* normals = nullptr;
  const std::vector<std::array<int32_t, 3>>* triangles = nullptr;
  const std::vector<double>* scalar = nullptr;  ///< per vertex
  double scalar_min = 0.0, scalar_max = 1.0;
  const std::vector<Rgb>* colours = nullptr;    ///< per vertex
  Rgb colour = {190, 190, 195};
  /// A ghost is blended with `opacity` over what is drawn, only where it lies more than
  /// `ghost_bias` (length unit) in front of it, and leaves the depth buffer alone.
  bool ghost = false;
  double opacity = 0.3;
  double ghost_bias = 0.0;
};

/// Draws meshes into an image of the given size (supersampled internally).
class Renderer {
 public:
  Renderer(int width, int height, const Camera& camera);
  void draw(const ShadedMesh& mesh);
  /// Where a point lands in the final image (pixels, top-left origin), if in front of the camera.
  std::optional<std::array<double, 2>> project(const Vec3& p) const;
  /// True if `p` is not hidden behind what is drawn (by more than `tolerance`, length unit).
  bool visible(const Vec3& p, double tolerance) const;
  /// Draws a vertical colour bar at the right edge with a title and min / max labels.
  void colour_bar(const std::string& title, double min, double max, const std::string& unit);
  /// Text at pixel (x, y) of the final image (top-left origin).
  void text(int x, int y, const std::string& s, const Rgb& colour, int scale = 2);
  /// Text wrapped into lines of at most `max_width` pixels; returns the y below the last line.
  int paragraph(int x, int y, const std::string& s, const Rgb& colour, int scale, int max_width);
  /// Text on a light box, centred on (x, y): a label next to something drawn.
  void label(double x, double y, const std::string& s, const Rgb& colour);
  /// Copies what `other` drew (colours and depths) with its top-left corner at pixel (x, y):
  /// panels side by side in one picture.
  void paste(const Renderer& other, int x, int y);
  /// Width in pixels of `s` drawn by `text` at `scale`.
  static int text_width(const std::string& s, int scale);
  int width() const { return w_ / ss_; }
  int height() const { return h_ / ss_; }
  /// The final (downsampled) image.
  Image image() const;

 private:
  void fill_rect(double x0, double y0, double x1, double y1, const Rgb& c, double alpha = 1.0);
  std::array<double, 3> shade(const ShadedMesh& mesh, const std::array<int32_t, 3>& tri, double w0, double w1, double w2,
                              const Vec3& light, const Vec3& view_dir) const;
  int w_, h_, ss_ = 2;
  Camera camera_;
  Eigen::Matrix4d view_proj_;
  std::vector<float> depth_;  // eye distance along the view axis
  std::vector<std::array<float, 3>> colour_;
};

}  // namespace softshell::demo
