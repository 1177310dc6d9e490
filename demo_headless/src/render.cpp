#include "render.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STB_IMAGE_WRITE_STATIC
#include <stb/stb_image_write.h>
#include <stb/stb_easy_font.h>

namespace softshell::demo {

Image::Image(int w, int h) : width(w), height(h), rgb(static_cast<size_t>(3 * w * h), 0) {}

void Image::set(int x, int y, const Rgb& c) {
  if (x < 0 || y < 0 || x >= width || y >= height) return;
  std::copy(c.begin(), c.end(), rgb.begin() + 3 * (static_cast<ptrdiff_t>(y) * width + x));
}

Rgb Image::at(int x, int y) const {
  const auto* p = rgb.data() + 3 * (static_cast<ptrdiff_t>(y) * width + x);
  return {p[0], p[1], p[2]};
}

Result<void> Image::write_png(const std::filesystem::path& path) const {
  if (!stbi_write_png(path.string().c_str(), width, height, 3, rgb.data(), 3 * width)) {
    return Error{ErrorCode::kIoError, "cannot write the PNG '" + path.string() + "'"};
  }
  return {};
}

Camera Camera::framing(const Vec3& lo, const Vec3& hi, const Vec3& from, const Vec3& up) {
  Camera c;
  c.target = 0.5 * (lo + hi);
  const double radius = 0.5 * (hi - lo).norm();
  // The bounding sphere just fits the view, with room for the caption.
  const double distance = 1.05 * radius / std::tan(0.5 * c.fov_deg * 3.14159265358979 / 180.0);
  c.eye = c.target + distance * from.normalized();
  c.up = up;
  return c;
}

Rgb viridis(double t) {
  static const double table[9][3] = {{68, 1, 84},    {71, 44, 122},  {59, 81, 139},   {44, 113, 142}, {33, 144, 141},
                                     {39, 173, 129}, {92, 200, 99},  {170, 220, 50},  {253, 231, 37}};
  t = std::clamp(std::isfinite(t) ? t : 0.0, 0.0, 1.0) * 8.0;
  const int i = std::min(static_cast<int>(t), 7);
  const double f = t - i;
  Rgb c;
  for (int k = 0; k < 3; ++k) c[static_cast<size_t>(k)] = static_cast<uint8_t>(table[i][k] * (1 - f) + table[i + 1][k] * f + 0.5);
  return c;
}

Renderer::Renderer(int width, int height, const Camera& camera)
    : w_(width * 2), h_(height * 2), camera_(camera),
      depth_(static_cast<size_t>(w_ * h_), std::numeric_limits<float>::infinity()),
      colour_(static_cast<size_t>(w_ * h_)) {
  // Background: a soft vertical gradient.
  for (int y = 0; y < h_; ++y) {
    const float t = static_cast<float>(y) / static_cast<float>(h_);
    for (int x = 0; x < w_; ++x) colour_[static_cast<size_t>(y * w_ + x)] = {245 - 35 * t, 247 - 35 * t, 250 - 30 * t};
  }
  const Vec3 f = (camera.target - camera.eye).normalized();
  const Vec3 s = f.cross(camera.up).normalized();
  const Vec3 u = s.cross(f);
  Eigen::Matrix4d view = Eigen::Matrix4d::Identity();
  view.block<1, 3>(0, 0) = s.transpose();
  view.block<1, 3>(1, 0) = u.transpose();
  view.block<1, 3>(2, 0) = -f.transpose();
  view(0, 3) = -s.dot(camera.eye);
  view(1, 3) = -u.dot(camera.eye);
  view(2, 3) = f.dot(camera.eye);
  const double aspect = static_cast<double>(w_) / h_;
  const double focal = 1.0 / std::tan(0.5 * camera.fov_deg * 3.14159265358979 / 180.0);
  const double near = 1e-3 * (camera.eye - camera.target).norm(), far = 1e3 * (camera.eye - camera.target).norm();
  Eigen::Matrix4d proj = Eigen::Matrix4d::Zero();
  proj(0, 0) = focal / aspect;
  proj(1, 1) = focal;
  proj(2, 2) = (far + near) / (near - far);
  proj(2, 3) = 2 * far * near / (near - far);
  proj(3, 2) = -1.0;
  view_proj_ = proj * view;
}

std::optional<std::array<double, 2>> Renderer::project(const Vec3& p) const {
  const Eigen::Vector4d clip = view_proj_ * Eigen::Vector4d(p.x(), p.y(), p.z(), 1.0);
  if (clip.w() <= 0.0) return std::nullopt;
  return std::array<double, 2>{(clip.x() / clip.w() * 0.5 + 0.5) * w_ / ss_, (0.5 - clip.y() / clip.w() * 0.5) * h_ / ss_};
}

bool Renderer::visible(const Vec3& p, double tolerance) const {
  const Eigen::Vector4d clip = view_proj_ * Eigen::Vector4d(p.x(), p.y(), p.z(), 1.0);
  if (clip.w() <= 0.0) return false;
  const int x = static_cast<int>((clip.x() / clip.w() * 0.5 + 0.5) * w_), y = static_cast<int>((0.5 - clip.y() / clip.w() * 0.5) * h_);
  if (x < 0 || y < 0 || x >= w_ || y >= h_) return false;
  return clip.w() <= depth_[static_cast<size_t>(y * w_ + x)] + tolerance;
}

std::array<double, 3> Renderer::shade(const ShadedMesh& mesh, const std::array<int32_t, 3>& tri, double w0, double w1,
                                      double w2, const Vec3& light, const Vec3& view_dir) const {
  const auto at = [&](int k) { return static_cast<size_t>(tri[static_cast<size_t>(k)]); };
  Vec3 n = w0 * (*mesh.normals)[at(0)] + w1 * (*mesh.normals)[at(1)] + w2 * (*mesh.normals)[at(2)];
  n.normalize();
  if (n.dot(view_dir) < 0) n = -n;  // two-sided lighting for open shells
  std::array<double, 3> base = {double(mesh.colour[0]), double(mesh.colour[1]), double(mesh.colour[2])};
  const double range = mesh.scalar_max - mesh.scalar_min;
  if (mesh.scalar && range > 0) {
    const double s = w0 * (*mesh.scalar)[at(0)] + w1 * (*mesh.scalar)[at(1)] + w2 * (*mesh.scalar)[at(2)];
    const Rgb c8 = viridis((s - mesh.scalar_min) / range);
    base = {double(c8[0]), double(c8[1]), double(c8[2])};
  } else if (mesh.colours) {
    for (size_t k = 0; k < 3; ++k) {
      base[k] = w0 * (*mesh.colours)[at(0)][k] + w1 * (*mesh.colours)[at(1)][k] + w2 * (*mesh.colours)[at(2)][k];
    }
  }
  const double diffuse = std::max(0.0, n.dot(light));
  const double specular = mesh.ghost ? 0.0 : std::pow(std::max(0.0, n.dot((light + view_dir).normalized())), 40.0);
  const double shade = mesh.ghost ? 0.75 + 0.25 * diffuse : 0.35 + 0.65 * diffuse;
  std::array<double, 3> out;
  for (size_t k = 0; k < 3; ++k) out[k] = std::min(255.0, base[k] * shade + 60.0 * specular);
  return out;
}

void Renderer::draw(const ShadedMesh& mesh) {
  const auto& verts = *mesh.vertices;
  // Project every vertex once: screen position and 1 / (eye distance), which is affine on screen.
  std::vector<Eigen::Vector3d> screen(verts.size());
  const double near = 1e-3 * (camera_.eye - camera_.target).norm();
  for (size_t i = 0; i < verts.size(); ++i) {
    const Eigen::Vector4d clip = view_proj_ * Eigen::Vector4d(verts[i].x(), verts[i].y(), verts[i].z(), 1.0);
    screen[i] = Eigen::Vector3d((clip.x() / clip.w() * 0.5 + 0.5) * w_, (0.5 - clip.y() / clip.w() * 0.5) * h_,
                                clip.w() > near ? 1.0 / clip.w() : -1.0);
  }
  const Vec3 light = ((camera_.eye - camera_.target).normalized() + 0.6 * camera_.up.normalized() +
                      0.3 * (camera_.eye - camera_.target).cross(camera_.up).normalized())
                         .normalized();
  const Vec3 view_dir = (camera_.eye - camera_.target).normalized();
  for (const auto& tri : *mesh.triangles) {
    const Eigen::Vector3d& a = screen[static_cast<size_t>(tri[0])];
    const Eigen::Vector3d& b = screen[static_cast<size_t>(tri[1])];
    const Eigen::Vector3d& c = screen[static_cast<size_t>(tri[2])];
    if (a.z() < 0 || b.z() < 0 || c.z() < 0) continue;  // behind (or too near) the camera
    const double area = (b.x() - a.x()) * (c.y() - a.y()) - (b.y() - a.y()) * (c.x() - a.x());
    if (area == 0.0) continue;
    const int x0 = std::max(0, static_cast<int>(std::floor(std::min({a.x(), b.x(), c.x()}))));
    const int x1 = std::min(w_ - 1, static_cast<int>(std::ceil(std::max({a.x(), b.x(), c.x()}))));
    const int y0 = std::max(0, static_cast<int>(std::floor(std::min({a.y(), b.y(), c.y()}))));
    const int y1 = std::min(h_ - 1, static_cast<int>(std::ceil(std::max({a.y(), b.y(), c.y()}))));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        const double px = x + 0.5, py = y + 0.5;
        const double w0 = ((b.x() - px) * (c.y() - py) - (b.y() - py) * (c.x() - px)) / area;
        const double w1 = ((c.x() - px) * (a.y() - py) - (c.y() - py) * (a.x() - px)) / area;
        const double w2 = 1.0 - w0 - w1;
        if (w0 < 0 || w1 < 0 || w2 < 0) continue;
        const double depth = 1.0 / (w0 * a.z() + w1 * b.z() + w2 * c.z());
        float& stored = depth_[static_cast<size_t>(y * w_ + x)];
        auto& out = colour_[static_cast<size_t>(y * w_ + x)];
        if (mesh.ghost) {
          // Fades in over a few biases in front of what is drawn, so its edges are soft.
          const double in_front = stored - depth - mesh.ghost_bias;
          if (!(in_front > 0.0)) continue;
          const double alpha = mesh.opacity * std::min(1.0, in_front / (3.0 * mesh.ghost_bias + 1e-300));
          const auto c3 = shade(mesh, tri, w0, w1, w2, light, view_dir);
          for (size_t k = 0; k < 3; ++k) out[k] = static_cast<float>((1.0 - alpha) * out[k] + alpha * c3[k]);
          continue;
        }
        if (depth >= stored) continue;
        stored = static_cast<float>(depth);
        const auto c3 = shade(mesh, tri, w0, w1, w2, light, view_dir);
        for (size_t k = 0; k < 3; ++k) out[k] = static_cast<float>(c3[k]);
      }
    }
  }
}

void Renderer::fill_rect(double x0, double y0, double x1, double y1, const Rgb& c, double alpha) {
  for (int y = std::max(0, static_cast<int>(y0)); y < std::min(h_, static_cast<int>(y1)); ++y) {
    for (int x = std::max(0, static_cast<int>(x0)); x < std::min(w_, static_cast<int>(x1)); ++x) {
      auto& out = colour_[static_cast<size_t>(y * w_ + x)];
      for (size_t k = 0; k < 3; ++k) out[k] = static_cast<float>((1.0 - alpha) * out[k] + alpha * c[k]);
    }
  }
}

void Renderer::paste(const Renderer& other, int x, int y) {
  for (int sy = 0; sy < other.h_; ++sy) {
    const int ty = y * ss_ + sy;
    if (ty < 0 || ty >= h_) continue;
    for (int sx = 0; sx < other.w_; ++sx) {
      const int tx = x * ss_ + sx;
      if (tx < 0 || tx >= w_) continue;
      colour_[static_cast<size_t>(ty * w_ + tx)] = other.colour_[static_cast<size_t>(sy * other.w_ + sx)];
      depth_[static_cast<size_t>(ty * w_ + tx)] = other.depth_[static_cast<size_t>(sy * other.w_ + sx)];
    }
  }
}

int Renderer::text_width(const std::string& s, int scale) {
  std::string copy = s;
  return stb_easy_font_width(copy.data()) * scale;
}

int Renderer::paragraph(int x, int y, const std::string& s, const Rgb& colour, int scale, int max_width) {
  std::string line, word;
  const int line_height = 12 * scale;
  const auto flush = [&] {
    if (!line.empty()) text(x, y, line, colour, scale);
    y += line_height;
    line.clear();
  };
  for (size_t i = 0; i <= s.size(); ++i) {
    if (i < s.size() && s[i] != ' ') {
      word += s[i];
      continue;
    }
    const std::string candidate = line.empty() ? word : line + " " + word;
    if (!line.empty() && text_width(candidate, scale) > max_width) {
      flush();
      line = word;
    } else {
      line = candidate;
    }
    word.clear();
  }
  flush();
  return y;
}

void Renderer::label(double x, double y, const std::string& s, const Rgb& colour) {
  const int w = text_width(s, 1), h = 10;
  const double left = x - 0.5 * w, top = y - 0.5 * h;
  fill_rect((left - 3) * ss_, (top - 2) * ss_, (left + w + 3) * ss_, (top + h + 1) * ss_, {255, 255, 255}, 0.8);
  text(static_cast<int>(std::lround(left)), static_cast<int>(std::lround(top)), s, colour, 1);
}

void Renderer::text(int x, int y, const std::string& s, const Rgb& colour, int scale) {
  std::vector<char> buffer(s.size() * 300 + 1000);
  std::string copy = s;
  const int quads = stb_easy_font_print(0, 0, copy.data(), nullptr, buffer.data(), static_cast<int>(buffer.size()));
  const double k = scale * ss_;
  for (int q = 0; q < quads; ++q) {
    const auto* v = reinterpret_cast<const float*>(buffer.data() + static_cast<size_t>(q) * 4 * 16);
    const double qx0 = v[0], qy0 = v[1], qx1 = v[2 * 4], qy1 = v[2 * 4 + 1];
    fill_rect(x * ss_ + qx0 * k, y * ss_ + qy0 * k, x * ss_ + qx1 * k, y * ss_ + qy1 * k, colour);
  }
}

void Renderer::colour_bar(const std::string& title, double min, double max, const std::string& unit) {
  const int width = w_ / ss_, height = h_ / ss_;
  const int bar_x = width - 70, bar_top = height / 6, bar_bottom = height - height / 6;
  for (int y = bar_top; y < bar_bottom; ++y) {
    const auto c = viridis(1.0 - static_cast<double>(y - bar_top) / (bar_bottom - bar_top));
    fill_rect(bar_x * ss_, y * ss_, (bar_x + 18) * ss_, (y + 1) * ss_, c);
  }
  char label[64];
  std::snprintf(label, sizeof label, "%.3g %s", max, unit.c_str());
  text(bar_x - 10, bar_top - 18, label, {30, 30, 30}, 1);
  std::snprintf(label, sizeof label, "%.3g", min);
  text(bar_x - 10, bar_bottom + 6, label, {30, 30, 30}, 1);
  text(width - 12 - text_width(title, 1), bar_top - 34, title, {30, 30, 30}, 1);
}

Image Renderer::image() const {
  Image out(w_ / ss_, h_ / ss_);
  for (int y = 0; y < out.height; ++y) {
    for (int x = 0; x < out.width; ++x) {
      std::array<float, 3> sum = {0, 0, 0};
      for (int dy = 0; dy < ss_; ++dy) {
        for (int dx = 0; dx < ss_; ++dx) {
          const auto& c = colour_[static_cast<size_t>((y * ss_ + dy) * w_ + x * ss_ + dx)];
          for (int k = 0; k < 3; ++k) sum[static_cast<size_t>(k)] += c[static_cast<size_t>(k)];
        }
      }
      out.set(x, y, {static_cast<uint8_t>(sum[0] / (ss_ * ss_) + 0.5f), static_cast<uint8_t>(sum[1] / (ss_ * ss_) + 0.5f),
                     static_cast<uint8_t>(sum[2] / (ss_ * ss_) + 0.5f)});
    }
  }
  return out;
}

}  // namespace softshell::demo
