#include "shell_benchmarks.h"

#include <cmath>

namespace softshell::test {

Plate make_plate(int n, double a, bool ghost_ring) { return make_rectangle(n, n, a, a, ghost_ring); }

Plate make_rectangle(int nx, int ny, double a, double b, bool ghost_ring) {
  Plate p;
  p.n = nx;
  p.ny = ny;
  p.ghost = ghost_ring;
  const int ring = ghost_ring ? 2 : 0, faces_x = nx + ring, faces_y = ny + ring;
  p.points_per_side = faces_x + 1;
  const double hx = a / nx, hy = b / ny;
  const double x0 = ghost_ring ? -hx : 0.0, y0 = ghost_ring ? -hy : 0.0;
  std::vector<Vec3> positions;
  for (int j = 0; j <= faces_y; ++j) {
    for (int i = 0; i <= faces_x; ++i) positions.emplace_back(x0 + i * hx, y0 + j * hy, 0.0);
  }
  std::vector<std::vector<int32_t>> quads;
  for (int j = 0; j < faces_y; ++j) {
    for (int i = 0; i < faces_x; ++i) {
      quads.push_back({p.index(i, j), p.index(i + 1, j), p.index(i + 1, j + 1), p.index(i, j + 1)});
    }
  }
  p.mesh = ControlMesh(std::move(positions), quads);
  if (ghost_ring) p.mesh.set_boundary(BoundaryMode::kNone);
  return p;
}

SurfacePoint Plate::at(double s, double t) const {
  const int offset = ghost ? 1 : 0;
  const int faces_x = n + 2 * offset;
  const int fi = std::min(static_cast<int>(s * n), n - 1), fj = std::min(static_cast<int>(t * ny), ny - 1);
  const double u = s * n - fi, v = t * ny - fj;
  return SurfacePoint{(fj + offset) * faces_x + fi + offset, 0, u, v};
}

SurfacePoint Plate::centre() const { return at(0.5, 0.5); }

std::vector<VertexConstraint> in_plane_fixed(const Plate& plate) {
  std::vector<VertexConstraint> out;
  for (int32_t v = 0; v < plate.mesh.num_vertices(); ++v) out.push_back({v, kAxisX | kAxisY, Vec3::Zero()});
  return out;
}

std::vector<VertexConstraint> simply_supported(const Plate& plate) {
  std::vector<VertexConstraint> out;
  const int last = plate.points_per_side - 1;
  for (int j = 0; j <= last; ++j) {
    for (int i = 0; i <= last; ++i) {
      const bool boundary = i == 0 || j == 0 || i == last || j == last;
      out.push_back({plate.index(i, j), boundary ? uint32_t{kAxisAll} : uint32_t{kAxisX | kAxisY}, Vec3::Zero()});
    }
  }
  return out;
}

ScordelisLo make_scordelis_lo(int nt, int nl) {
  ScordelisLo roof;
  roof.nt = nt;
  roof.nl = nl;
  constexpr double kPi = 3.14159265358979323846;
  const double half = ScordelisLo::kHalfAngleDeg * kPi / 180.0;
  // Control points around the arc whose cubic B-spline limit (end points interpolated, phantom
  // end rule) passes through the circle at every node: solve the tridiagonal system
  // P0 = X0, Pn = Xn, (P_{i-1} + 4 P_i + P_{i+1}) / 6 = X_i.
  auto fit = [&](auto coordinate) {
    std::vector<double> x(static_cast<size_t>(nt + 1));
    for (int i = 0; i <= nt; ++i) x[static_cast<size_t>(i)] = coordinate(-half + 2.0 * half * i / nt);
    std::vector<double> a(x.size(), 1.0 / 6.0), b(x.size(), 4.0 / 6.0), c(x.size(), 1.0 / 6.0), d = x;
    b.front() = b.back() = 1.0;
    c.front() = a.back() = 0.0;
    for (size_t i = 1; i < x.size(); ++i) {  // Thomas algorithm
      const double w = a[i] / b[i - 1];
      b[i] -= w * c[i - 1];
      d[i] -= w * d[i - 1];
    }
    const size_t n = x.size();
    std::vector<double> p(n);
    p[n - 1] = d[n - 1] / b[n - 1];
    for (size_t i = n - 1; i-- > 0;) p[i] = (d[i] - c[i] * p[i + 1]) / b[i];
    return p;
  };
  const std::vector<double> px = fit([](double t) { return ScordelisLo::kRadius * std::sin(t); });
  const std::vector<double> pz = fit([](double t) { return ScordelisLo::kRadius * std::cos(t); });
  std::vector<Vec3> positions;
  for (int j = 0; j <= nl; ++j) {
    for (int i = 0; i <= nt; ++i) {
      positions.emplace_back(px[static_cast<size_t>(i)], ScordelisLo::kLength * j / nl, pz[static_cast<size_t>(i)]);
    }
  }
  std::vector<std::vector<int32_t>> quads;
  for (int j = 0; j < nl; ++j) {
    for (int i = 0; i < nt; ++i) {
      // Counter-clockwise seen from outside (+z at the crown).
      quads.push_back({roof.index(i, j), roof.index(i + 1, j), roof.index(i + 1, j + 1), roof.index(i, j + 1)});
    }
  }
  roof.mesh = ControlMesh(std::move(positions), quads);
  return roof;
}

SurfacePoint ScordelisLo::free_edge_midpoint() const {
  // Corner (0, 0) of face (0, nl / 2) is the grid vertex at theta = -40 degrees, y = L / 2.
  return SurfacePoint{(nl / 2) * nt, 0, 0.0, 0.0};
}

std::vector<VertexConstraint> ScordelisLo::supports() const {
  std::vector<VertexConstraint> out;
  for (int j : {0, nl}) {
    for (int i = 0; i <= nt; ++i) out.push_back({index(i, j), kAxisX | kAxisZ, Vec3::Zero()});
  }
  out.push_back({index(nt / 2, 0), kAxisY, Vec3::Zero()});  // axial rigid motion only
  return out;
}

}  // namespace softshell::test
