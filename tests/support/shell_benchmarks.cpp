#include "shell_benchmarks.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <random>

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

GhostGrid make_ghost_grid(int nu, int nv, const std::function<Vec3(int, int)>& position) {
  GhostGrid g;
  g.nu = nu;
  g.nv = nv;
  std::vector<Vec3> positions;
  for (int j = -1; j <= nv + 1; ++j) {
    for (int i = -1; i <= nu + 1; ++i) positions.push_back(position(i, j));
  }
  std::vector<std::vector<int32_t>> quads;
  for (int j = -1; j <= nv; ++j) {
    for (int i = -1; i <= nu; ++i) quads.push_back({g.index(i, j), g.index(i + 1, j), g.index(i + 1, j + 1), g.index(i, j + 1)});
  }
  g.mesh = ControlMesh(std::move(positions), quads);
  g.mesh.set_boundary(BoundaryMode::kNone);
  return g;
}

SurfacePoint GhostGrid::at(double s, double t) const {
  const int fi = std::min(static_cast<int>(s * nu), nu - 1), fj = std::min(static_cast<int>(t * nv), nv - 1);
  return SurfacePoint{(fj + 1) * (nu + 2) + fi + 1, 0, s * nu - fi, t * nv - fj};
}

void add_mirror_planes(const GhostGrid& grid, const MirrorPlanes& planes, DeformationRequest& request) {
  // The partner of a ghost index across a mirror plane (itself if the edge is free or the index
  // is not a ghost), and the reflection that maps the partner's displacement onto the ghost's.
  auto partner = [](int k, int n, int low_axis, int high_axis, Vec3& reflection) {
    if (k == -1 && low_axis >= 0) {
      reflection[low_axis] = -reflection[low_axis];
      return 1;
    }
    if (k == n + 1 && high_axis >= 0) {
      reflection[high_axis] = -reflection[high_axis];
      return n - 1;
    }
    return k;
  };
  for (int j = -1; j <= grid.nv + 1; ++j) {
    for (int i = -1; i <= grid.nu + 1; ++i) {
      Vec3 reflection = Vec3::Ones();
      const int pi = partner(i, grid.nu, planes.i_min, planes.i_max, reflection);
      const int pj = partner(j, grid.nv, planes.j_min, planes.j_max, reflection);
      if (pi != i || pj != j) {  // u(ghost) = M u(partner); the partner is never tied itself
        request.lagrange_constraints.push_back(
            {{grid.index(i, j), grid.index(pi, pj)}, {Vec3::Ones(), -reflection}, Vec3::Zero()});
        continue;
      }
      uint32_t mask = 0;  // in a plane: no motion along its normal
      if (i == 0 && planes.i_min >= 0) mask |= 1u << planes.i_min;
      if (i == grid.nu && planes.i_max >= 0) mask |= 1u << planes.i_max;
      if (j == 0 && planes.j_min >= 0) mask |= 1u << planes.j_min;
      if (j == grid.nv && planes.j_max >= 0) mask |= 1u << planes.j_max;
      if (mask != 0) request.vertex_constraints.push_back({grid.index(i, j), mask, Vec3::Zero()});
    }
  }
}

namespace {
constexpr double kPiValue = 3.14159265358979323846;
// A ring of control points at radius r c(d) has its limit points at radius r: c = 6 / (4 + 2 cos d).
double ring_scale(double step) { return 6.0 / (4.0 + 2.0 * std::cos(step)); }
}  // namespace

PulloutCylinder make_pullout_cylinder(int nt, int nl) {
  PulloutCylinder c;
  const double dtheta = 0.5 * kPiValue / nt, dy = 0.5 * PulloutCylinder::kLength / nl;
  const double r = PulloutCylinder::kRadius * ring_scale(dtheta);
  c.grid = make_ghost_grid(nt, nl, [&](int i, int j) {
    return Vec3(r * std::cos(i * dtheta), j * dy, r * std::sin(i * dtheta));
  });
  return c;
}

DeformationRequest PulloutCylinder::request(double load) const {
  DeformationRequest request;
  add_mirror_planes(grid, MirrorPlanes{2, 0, -1, 1}, request);
  request.surface_forces.push_back({a(), Vec3(0.0, 0.0, load / 4.0)});
  return request;
}

OpenHemisphere make_open_hemisphere(int nphi, int npsi) {
  OpenHemisphere h;
  const double dphi = 0.5 * kPiValue / nphi;
  const double equator = 0.5 * kPiValue, hole = OpenHemisphere::kHoleDeg * kPiValue / 180.0;
  const double dpsi = (equator - hole) / npsi;
  // Tensor-product weights: the limit of vertex (i, j) scales x, y by both ring factors, z by one.
  const double sphi = ring_scale(dphi), spsi = ring_scale(dpsi);
  h.grid = make_ghost_grid(nphi, npsi, [&](int i, int j) {
    const double phi = i * dphi, psi = equator - j * dpsi;  // colatitude
    const double rho = OpenHemisphere::kRadius * std::sin(psi) * sphi * spsi;
    return Vec3(rho * std::cos(phi), rho * std::sin(phi), OpenHemisphere::kRadius * std::cos(psi) * spsi);
  });
  return h;
}

DeformationRequest OpenHemisphere::request(double load) const {
  DeformationRequest request;
  add_mirror_planes(grid, MirrorPlanes{1, 0, -1, -1}, request);
  request.vertex_constraints.push_back({grid.index(1, grid.nv), kAxisZ, Vec3::Zero()});
  request.surface_forces.push_back({a(), Vec3(load / 2.0, 0.0, 0.0)});
  request.surface_forces.push_back({b(), Vec3(0.0, -load / 2.0, 0.0)});
  return request;
}

ControlMesh fan_plate(int valence, int k, int sectors) {
  if (sectors < 0) sectors = valence;
  const bool closed = sectors == valence;
  constexpr double kPi = 3.14159265358979323846;
  auto axis = [&](int i) {
    const double angle = 2.0 * kPi * i / valence;
    return Vec3(std::cos(angle), std::sin(angle), 0.0);
  };
  // Grid point (a, b) of sector i is a e_i + b e_{i+1}; sector i's b-axis is sector i+1's a-axis.
  std::vector<Vec3> positions{Vec3::Zero()};
  const auto side = static_cast<size_t>(k + 1);
  std::vector<std::vector<int32_t>> id(static_cast<size_t>(sectors + 1), std::vector<int32_t>(side * side, 0));
  for (int i = 0; i <= sectors; ++i) {  // the a-axes (one more for an open fan's last b-axis)
    if (i == sectors && closed) break;
    for (int a = 1; a <= k; ++a) {
      id[static_cast<size_t>(i)][static_cast<size_t>(a)] = static_cast<int32_t>(positions.size());
      positions.push_back(a * axis(i));
    }
  }
  for (int i = 0; i < sectors; ++i) {
    auto& sector = id[static_cast<size_t>(i)];
    const auto next = static_cast<size_t>(closed ? (i + 1) % valence : i + 1);
    for (int b = 1; b <= k; ++b) sector[side * static_cast<size_t>(b)] = id[next][static_cast<size_t>(b)];
    for (int b = 1; b <= k; ++b) {
      for (int a = 1; a <= k; ++a) {
        sector[static_cast<size_t>(a) + side * static_cast<size_t>(b)] = static_cast<int32_t>(positions.size());
        positions.push_back(a * axis(i) + b * axis(i + 1));
      }
    }
  }
  std::vector<std::vector<int32_t>> faces;
  for (int i = 0; i < sectors; ++i) {
    const auto& sector = id[static_cast<size_t>(i)];
    for (size_t b = 0; b < side - 1; ++b) {
      for (size_t a = 0; a < side - 1; ++a) {
        faces.push_back({sector[a + side * b], sector[a + 1 + side * b], sector[a + 1 + side * (b + 1)],
                         sector[a + side * (b + 1)]});
      }
    }
  }
  return ControlMesh(std::move(positions), faces);
}

ControlMesh ngon_plate(int n, int rings) {
  constexpr double kPi = 3.14159265358979323846;
  std::vector<Vec3> positions;
  for (int r = 1; r <= rings + 1; ++r) {
    for (int i = 0; i < n; ++i) {
      const double angle = 2.0 * kPi * (i + 0.3 * (r % 2)) / n;
      positions.push_back(r * Vec3(std::cos(angle), std::sin(angle), 0.0));
    }
  }
  std::vector<std::vector<int32_t>> faces;
  std::vector<int32_t> centre;
  for (int i = 0; i < n; ++i) centre.push_back(i);
  faces.push_back(centre);
  for (int r = 0; r < rings; ++r) {
    for (int i = 0; i < n; ++i) {
      const int next = (i + 1) % n;
      faces.push_back({r * n + next, r * n + i, (r + 1) * n + i, (r + 1) * n + next});
    }
  }
  return ControlMesh(std::move(positions), faces);
}

std::vector<char> boundary_points(const ControlMesh& mesh) {
  std::map<std::pair<int32_t, int32_t>, int> edges;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    auto fv = mesh.face(f);
    for (size_t i = 0; i < fv.size(); ++i) {
      const int32_t a = fv[i], b = fv[(i + 1) % fv.size()];
      ++edges[{std::min(a, b), std::max(a, b)}];
    }
  }
  std::vector<char> out(static_cast<size_t>(mesh.num_vertices()), 0);
  for (const auto& [edge, count] : edges) {
    if (count == 1) out[static_cast<size_t>(edge.first)] = out[static_cast<size_t>(edge.second)] = 1;
  }
  return out;
}

void perturb_interior(ControlMesh& mesh, double amount, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uni(-amount, amount);
  const std::vector<char> boundary = boundary_points(mesh);
  for (size_t v = 0; v < boundary.size(); ++v) {
    if (!boundary[v]) mesh.positions()[v] += Vec3(uni(rng), uni(rng), 0.0);
  }
}

EvPlate make_ev_plate(int n, double a) {
  EvPlate plate;
  const int b1 = n / 4, b2 = 3 * n / 4;
  auto block_point = [&](int i, int j) { return (i == b1 && j == b1) || (i == b2 && j == b2); };
  auto block_cell = [&](int i, int j) {
    return ((i == b1 - 1 || i == b1) && (j == b1 - 1 || j == b1)) || ((i == b2 - 1 || i == b2) && (j == b2 - 1 || j == b2));
  };
  std::vector<Vec3> positions;
  std::map<std::pair<int, int>, int32_t> id;
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) {
      if (block_point(i, j)) continue;
      id[{i, j}] = static_cast<int32_t>(positions.size());
      positions.emplace_back(a * i / n, a * j / n, 0.0);
    }
  }
  std::vector<std::vector<int32_t>> faces;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      if (block_cell(i, j)) continue;
      if (i == n / 2 && j == n / 2) plate.centre = SurfacePoint{static_cast<int32_t>(faces.size()), 0, 0.0, 0.0};
      faces.push_back({id[{i, j}], id[{i + 1, j}], id[{i + 1, j + 1}], id[{i, j + 1}]});
    }
  }
  for (int block = 0; block < 2; ++block) {
    // The second block is the first turned by 180 degrees about the centre.
    const int c = block == 0 ? b1 : b2, d = block == 0 ? 1 : -1;
    const Vec3 centre(a * c / n, a * c / n, 0.0);
    const auto p = static_cast<int32_t>(positions.size());
    positions.push_back(centre + d * Vec3(-0.4 * a / n, 0.0, 0.0));
    const auto q = static_cast<int32_t>(positions.size());
    positions.push_back(centre + d * Vec3(0.4 * a / n, 0.0, 0.0));
    auto r = [&](int di, int dj) { return id[{c + d * di, c + d * dj}]; };
    const int32_t r0 = r(-1, -1), r1 = r(0, -1), r2 = r(1, -1), r3 = r(1, 0), r4 = r(1, 1), r5 = r(0, 1), r6 = r(-1, 1),
                  r7 = r(-1, 0);
    faces.push_back({r0, r1, p, r7});
    faces.push_back({r1, r2, r3, q});
    faces.push_back({r1, q, p});
    faces.push_back({q, r3, r4, r5});
    faces.push_back({r5, r6, r7, p});
    faces.push_back({p, q, r5});
  }
  plate.mesh = ControlMesh(std::move(positions), faces);
  return plate;
}

std::vector<LagrangeConstraint> turned_tangents(const LimitEvaluator& evaluator, const std::vector<SurfacePoint>& points,
                                                const Eigen::Matrix3d& rotation) {
  std::vector<LagrangeConstraint> rows;
  for (const SurfacePoint& p : points) {
    const LimitStencil st = evaluator.stencil(p);
    const Vec3 a1 = evaluator.evaluate(p).du;
    LagrangeConstraint c;
    for (size_t k = 0; k < st.size(); ++k) {
      c.indices.push_back(st.indices[k]);
      c.coefficients.push_back(Vec3::Constant(st.du[k]));
    }
    c.values = rotation * a1 - a1;
    rows.push_back(std::move(c));
  }
  return rows;
}

std::vector<VertexConstraint> bottom_supports(const ControlMesh& mesh, const std::vector<int32_t>& component_of) {
  std::map<int32_t, std::vector<int32_t>> parts;
  for (size_t v = 0; v < component_of.size(); ++v) parts[component_of[v]].push_back(static_cast<int32_t>(v));
  std::vector<VertexConstraint> supports;
  for (auto& [part, points] : parts) {
    std::stable_sort(points.begin(), points.end(), [&](int32_t a, int32_t b) {
      return mesh.positions()[static_cast<size_t>(a)].y() < mesh.positions()[static_cast<size_t>(b)].y();
    });
    points.resize(std::min(points.size(), std::max<size_t>(4, points.size() / 20)));
    for (int32_t v : points) supports.push_back({v, kAxisAll, Vec3::Zero()});
  }
  return supports;
}

SurfacePoint topmost_face_centre(const LimitEvaluator& limit) {
  SurfacePoint grab{0, 0, 0.5, 0.5};
  double top = -1e300;
  for (int32_t f = 0; f < limit.mesh().num_faces(); ++f) {
    const SurfacePoint p{f, 0, 0.5, 0.5};
    if (!limit.check(p).ok()) continue;
    const double y = limit.evaluate(p).position.y();
    if (y > top) {
      top = y;
      grab = p;
    }
  }
  return grab;
}

}  // namespace softshell::test
