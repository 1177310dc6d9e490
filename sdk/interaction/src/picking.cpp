// Picking: the triangle BVH (build, refit, ray and box queries), the Newton refinement of a ray hit
// onto the exact limit surface (walking across faces), and the Picker that joins them. (Long: the
// three are one pipeline and share the ray and box kernels at the top; each part is one section.)
#include "softshell/picking.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

namespace softshell {

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

bool finite(const Vec3& v) { return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z()); }

std::string str(const Vec3& v) {
  return "(" + std::to_string(v.x()) + ", " + std::to_string(v.y()) + ", " + std::to_string(v.z()) + ")";
}

// ------------------------------------------------------------------------------------------------
// Axis-aligned boxes

struct Box {
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity());
  Vec3 hi = Vec3::Constant(-std::numeric_limits<double>::infinity());
  void grow(const Vec3& p) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  void grow(const Box& b) {
    lo = lo.cwiseMin(b.lo);
    hi = hi.cwiseMax(b.hi);
  }
  bool empty() const { return !(lo.x() <= hi.x()); }
  double half_area() const {
    if (empty()) return 0.0;
    const Vec3 e = hi - lo;
    return e.x() * e.y() + e.y() * e.z() + e.z() * e.x();
  }
};

// Conservative factor for the slab test's far distance (Ize, "Robust BVH Ray Traversal", 2013):
// 1 + 2 gamma(3) in double precision.
constexpr double kSlabSlack = 1.0 + 2.0 * (3.0 * 0x1p-53) / (1.0 - 3.0 * 0x1p-53);

// Per-ray constants of the traversal and of the watertight triangle test.
struct RayPrep {
  Vec3 origin;
  Vec3 inv;  // 1 / direction with zeros replaced by a huge finite value (no 0 * inf = NaN)
  int kx = 0, ky = 1, kz = 2;
  double sx = 0.0, sy = 0.0, sz = 1.0;
  Vec3 direction;

  explicit RayPrep(const Ray& ray) : origin(ray.origin), direction(ray.direction) {
    for (int a = 0; a < 3; ++a) {
      const double d = ray.direction[a];
      inv[a] = d != 0.0 ? 1.0 / d : std::copysign(1e300, d);
    }
    // Watertight test: z is the dominant axis; swap x and y to keep the winding when d_z < 0.
    const Vec3 ad = ray.direction.cwiseAbs();
    kz = ad.x() > ad.y() ? (ad.x() > ad.z() ? 0 : 2) : (ad.y() > ad.z() ? 1 : 2);
    kx = (kz + 1) % 3;
    ky = (kx + 1) % 3;
    if (ray.direction[kz] < 0.0) std::swap(kx, ky);
    sx = ray.direction[kx] / ray.direction[kz];
    sy = ray.direction[ky] / ray.direction[kz];
    sz = 1.0 / ray.direction[kz];
  }
};

// Entry distance of the ray into [lo, hi] if it enters within [t_min, t_max], else +infinity.
inline double slab(const RayPrep& r, const double lo[3], const double hi[3], double t_min, double t_max) {
  double t0 = t_min, t1 = t_max;
  for (int a = 0; a < 3; ++a) {
    double near = (lo[a] - r.origin[a]) * r.inv[a];
    double far = (hi[a] - r.origin[a]) * r.inv[a];
    if (near > far) std::swap(near, far);
    far *= kSlabSlack;
    t0 = near > t0 ? near : t0;
    t1 = far < t1 ? far : t1;
  }
  return t0 <= t1 ? t0 : std::numeric_limits<double>::infinity();
}

// Watertight ray-triangle intersection (Woop, Benthin, Wald, JCGT 2013) in double precision.
// Edges and vertices count as inside, so a ray through a shared edge hits at least one triangle.
inline bool hit_triangle(const RayPrep& r, const std::array<Vec3, 3>& v, double t_min, double t_max, bool cull,
                         double& out_t, std::array<double, 3>& out_bary) {
  const Vec3 a = v[0] - r.origin, b = v[1] - r.origin, c = v[2] - r.origin;
  const double ax = a[r.kx] - r.sx * a[r.kz], ay = a[r.ky] - r.sy * a[r.kz];
  const double bx = b[r.kx] - r.sx * b[r.kz], by = b[r.ky] - r.sy * b[r.kz];
  const double cx = c[r.kx] - r.sx * c[r.kz], cy = c[r.ky] - r.sy * c[r.kz];
  const double u = cx * by - cy * bx;
  const double w_v = ax * cy - ay * cx;
  const double w = bx * ay - by * ax;
  if ((u < 0.0 || w_v < 0.0 || w < 0.0) && (u > 0.0 || w_v > 0.0 || w > 0.0)) return false;
  const double det = u + w_v + w;
  if (det == 0.0 || !std::isfinite(det)) return false;
  if (cull) {
    // Front side: the counter-clockwise normal points against the ray.
    const Vec3 n = (v[1] - v[0]).cross(v[2] - v[0]);
    if (n.dot(r.direction) >= 0.0) return false;
  }
  const double az = r.sz * a[r.kz], bz = r.sz * b[r.kz], cz = r.sz * c[r.kz];
  const double t = (u * az + w_v * bz + w * cz) / det;
  if (!(t >= t_min && t <= t_max)) return false;
  out_t = t;
  out_bary = {u / det, w_v / det, w / det};
  return true;
}

}  // namespace

Result<void> check_ray(const Ray& ray) {
  if (!finite(ray.origin)) return Error{ErrorCode::kInvalidArgument, "ray origin is not finite: " + str(ray.origin)};
  if (!finite(ray.direction)) {
    return Error{ErrorCode::kInvalidArgument, "ray direction is not finite: " + str(ray.direction)};
  }
  if (ray.direction.squaredNorm() == 0.0 || !std::isfinite(ray.direction.squaredNorm())) {
    return Error{ErrorCode::kInvalidArgument, "ray direction must be non-zero (and its length finite)"};
  }
  if (std::isnan(ray.t_min) || std::isnan(ray.t_max) || ray.t_max < ray.t_min || ray.t_min == HUGE_VAL) {
    return Error{ErrorCode::kInvalidArgument, "ray limits must satisfy t_min <= t_max, got [" +
                                                  std::to_string(ray.t_min) + ", " + std::to_string(ray.t_max) + "]"};
  }
  return {};
}

// ------------------------------------------------------------------------------------------------
// TriangleBvh

TriangleBvh::TriangleBvh() = default;

Result<TriangleBvh> TriangleBvh::build(std::span<const Vec3> vertices,
                                       std::span<const std::array<int32_t, 3>> triangles, const Options& options) {
  return capture([&]() -> TriangleBvh {
    const auto start = Clock::now();
    if (options.max_leaf_size < 1 || options.max_leaf_size > 32) {
      fail(ErrorCode::kInvalidArgument, "TriangleBvh: max_leaf_size must be in 1..32");
    }
    if (options.bins < 2 || options.bins > 64) fail(ErrorCode::kInvalidArgument, "TriangleBvh: bins must be in 2..64");
    if (triangles.size() > static_cast<size_t>(std::numeric_limits<int32_t>::max() / 2)) {
      fail(ErrorCode::kResourceExhausted, "TriangleBvh: too many triangles");
    }
    for (size_t i = 0; i < vertices.size(); ++i) {
      if (!finite(vertices[i])) fail(ErrorCode::kInvalidArgument, "TriangleBvh: vertex " + std::to_string(i) + " is not finite");
    }
    const auto nv = static_cast<int64_t>(vertices.size());
    for (size_t t = 0; t < triangles.size(); ++t) {
      for (int32_t i : triangles[t]) {
        if (i < 0 || i >= nv) {
          fail(ErrorCode::kInvalidArgument, "TriangleBvh: triangle " + std::to_string(t) + " uses vertex " +
                                                std::to_string(i) + ", out of range (" + std::to_string(nv) + " vertices)");
        }
      }
    }

    TriangleBvh bvh;
    bvh.num_vertices_ = vertices.size();
    const size_t nt = triangles.size();
    std::vector<Box> boxes(nt);
    std::vector<Vec3> centroids(nt);
    for (size_t t = 0; t < nt; ++t) {
      for (int32_t i : triangles[t]) boxes[t].grow(vertices[static_cast<size_t>(i)]);
      centroids[t] = 0.5 * (boxes[t].lo + boxes[t].hi);
    }
    bvh.tri_index_.resize(nt);
    for (size_t t = 0; t < nt; ++t) bvh.tri_index_[t] = static_cast<int32_t>(t);

    if (nt > 0) {
      bvh.nodes_.reserve(2 * nt / static_cast<size_t>(options.max_leaf_size) + 1);
      bvh.nodes_.push_back(Node{});
      struct Task {
        int32_t node, begin, end, depth;
      };
      std::vector<Task> stack{{0, 0, static_cast<int32_t>(nt), 1}};
      const int bins = options.bins;
      std::vector<Box> bin_box(static_cast<size_t>(bins));
      std::vector<int32_t> bin_count(static_cast<size_t>(bins));
      std::vector<double> right_area(static_cast<size_t>(bins));
      std::vector<int32_t> right_count(static_cast<size_t>(bins));
      while (!stack.empty()) {
        const Task task = stack.back();
        stack.pop_back();
        bvh.stats_.depth = std::max(bvh.stats_.depth, task.depth);
        Box bounds, centre_bounds;
        for (int32_t i = task.begin; i < task.end; ++i) {
          const auto t = static_cast<size_t>(bvh.tri_index_[static_cast<size_t>(i)]);
          bounds.grow(boxes[t]);
          centre_bounds.grow(centroids[t]);
        }
        Node& node = bvh.nodes_[static_cast<size_t>(task.node)];
        for (int a = 0; a < 3; ++a) {
          node.lo[a] = bounds.lo[a];
          node.hi[a] = bounds.hi[a];
        }
        const int32_t count = task.end - task.begin;
        if (count <= options.max_leaf_size) {
          node.first = task.begin;
          node.count = count;
          continue;
        }

        // Binned SAH over the three axes.
        int best_axis = -1, best_split = -1;
        double best_cost = std::numeric_limits<double>::infinity();
        const Vec3 extent = centre_bounds.hi - centre_bounds.lo;
        for (int axis = 0; axis < 3; ++axis) {
          if (!(extent[axis] > 0.0)) continue;
          const double scale = bins / extent[axis];
          std::fill(bin_box.begin(), bin_box.end(), Box{});
          std::fill(bin_count.begin(), bin_count.end(), 0);
          for (int32_t i = task.begin; i < task.end; ++i) {
            const auto t = static_cast<size_t>(bvh.tri_index_[static_cast<size_t>(i)]);
            const int b = std::min(bins - 1, static_cast<int>((centroids[t][axis] - centre_bounds.lo[axis]) * scale));
            bin_box[static_cast<size_t>(b)].grow(boxes[t]);
            ++bin_count[static_cast<size_t>(b)];
          }
          Box acc;
          int32_t n = 0;
          for (int b = bins - 1; b > 0; --b) {
            acc.grow(bin_box[static_cast<size_t>(b)]);
            n += bin_count[static_cast<size_t>(b)];
            right_area[static_cast<size_t>(b)] = acc.half_area();
            right_count[static_cast<size_t>(b)] = n;
          }
          acc = Box{};
          n = 0;
          for (int b = 0; b < bins - 1; ++b) {
            acc.grow(bin_box[static_cast<size_t>(b)]);
            n += bin_count[static_cast<size_t>(b)];
            const int32_t nr = right_count[static_cast<size_t>(b + 1)];
            if (n == 0 || nr == 0) continue;
            const double cost = acc.half_area() * n + right_area[static_cast<size_t>(b + 1)] * nr;
            if (cost < best_cost) {
              best_cost = cost;
              best_axis = axis;
              best_split = b;
            }
          }
        }

        int32_t mid = -1;
        auto* begin = bvh.tri_index_.data() + task.begin;
        auto* end = bvh.tri_index_.data() + task.end;
        if (best_axis >= 0 && task.depth < 200) {
          const double scale = bins / extent[best_axis];
          auto* split = std::partition(begin, end, [&](int32_t t) {
            const int b = std::min(
                bins - 1, static_cast<int>((centroids[static_cast<size_t>(t)][best_axis] - centre_bounds.lo[best_axis]) * scale));
            return b <= best_split;
          });
          mid = static_cast<int32_t>(split - bvh.tri_index_.data());
        }
        if (mid <= task.begin || mid >= task.end) {
          // All centroids coincide (or a pathological depth): split the range in half.
          mid = task.begin + count / 2;
          const int axis = static_cast<int>(std::max_element(extent.data(), extent.data() + 3) - extent.data());
          std::nth_element(begin, bvh.tri_index_.data() + mid, end, [&](int32_t x, int32_t y) {
            return centroids[static_cast<size_t>(x)][axis] < centroids[static_cast<size_t>(y)][axis];
          });
        }
        const auto left = static_cast<int32_t>(bvh.nodes_.size());
        bvh.nodes_[static_cast<size_t>(task.node)].first = left;
        bvh.nodes_[static_cast<size_t>(task.node)].count = 0;
        bvh.nodes_.push_back(Node{});
        bvh.nodes_.push_back(Node{});
        stack.push_back({left + 1, mid, task.end, task.depth + 1});
        stack.push_back({left, task.begin, mid, task.depth + 1});
      }
    }

    bvh.tri_verts_.resize(nt);
    bvh.tri_pos_.resize(nt);
    for (size_t i = 0; i < nt; ++i) {
      const auto& tri = triangles[static_cast<size_t>(bvh.tri_index_[i])];
      bvh.tri_verts_[i] = tri;
      for (size_t c = 0; c < 3; ++c) bvh.tri_pos_[i][c] = vertices[static_cast<size_t>(tri[c])];
    }
    bvh.stats_.nodes = static_cast<int32_t>(bvh.nodes_.size());
    for (const Node& n : bvh.nodes_) bvh.stats_.leaves += n.count > 0 ? 1 : 0;
    bvh.stats_.build_ms = ms_since(start);
    return bvh;
  });
}

void TriangleBvh::refit_nodes() {
  // Children always come after their parent, so one backward sweep updates every box.
  for (size_t k = nodes_.size(); k-- > 0;) {
    Node& n = nodes_[k];
    Box b;
    if (n.count > 0) {
      for (int32_t i = n.first; i < n.first + n.count; ++i) {
        for (const Vec3& p : tri_pos_[static_cast<size_t>(i)]) b.grow(p);
      }
    } else {
      const Node& l = nodes_[static_cast<size_t>(n.first)];
      const Node& r = nodes_[static_cast<size_t>(n.first + 1)];
      for (int a = 0; a < 3; ++a) {
        b.lo[a] = std::min(l.lo[a], r.lo[a]);
        b.hi[a] = std::max(l.hi[a], r.hi[a]);
      }
    }
    for (int a = 0; a < 3; ++a) {
      n.lo[a] = b.lo[a];
      n.hi[a] = b.hi[a];
    }
  }
}

Result<void> TriangleBvh::refit(std::span<const Vec3> vertices) {
  const auto start = Clock::now();
  if (vertices.size() != num_vertices_) {
    return Error{ErrorCode::kInvalidArgument, "TriangleBvh::refit: expected " + std::to_string(num_vertices_) +
                                                  " vertices, got " + std::to_string(vertices.size())};
  }
  for (size_t i = 0; i < vertices.size(); ++i) {
    if (!finite(vertices[i])) {
      return Error{ErrorCode::kInvalidArgument, "TriangleBvh::refit: vertex " + std::to_string(i) + " is not finite"};
    }
  }
  for (size_t i = 0; i < tri_verts_.size(); ++i) {
    for (size_t c = 0; c < 3; ++c) tri_pos_[i][c] = vertices[static_cast<size_t>(tri_verts_[i][c])];
  }
  refit_nodes();
  stats_.refit_ms = ms_since(start);
  return {};
}

std::optional<TriangleHit> TriangleBvh::intersect(const Ray& ray, bool cull_back_faces) const {
  if (nodes_.empty()) return std::nullopt;
  const RayPrep r(ray);
  double t_best = ray.t_max;
  int32_t best = -1;
  std::array<double, 3> bary_best{};
  constexpr int kStack = 256;  // depth is bounded by ~200 at build time
  int32_t stack[kStack];
  int sp = 0;
  if (slab(r, nodes_[0].lo, nodes_[0].hi, ray.t_min, t_best) == std::numeric_limits<double>::infinity()) {
    return std::nullopt;
  }
  stack[sp++] = 0;
  while (sp > 0) {
    const Node& node = nodes_[static_cast<size_t>(stack[--sp])];
    if (node.count > 0) {
      for (int32_t i = node.first; i < node.first + node.count; ++i) {
        double t;
        std::array<double, 3> bary;
        if (hit_triangle(r, tri_pos_[static_cast<size_t>(i)], ray.t_min, t_best, cull_back_faces, t, bary)) {
          t_best = t;
          best = i;
          bary_best = bary;
        }
      }
      continue;
    }
    const int32_t l = node.first, rr = node.first + 1;
    const double tl = slab(r, nodes_[static_cast<size_t>(l)].lo, nodes_[static_cast<size_t>(l)].hi, ray.t_min, t_best);
    const double tr = slab(r, nodes_[static_cast<size_t>(rr)].lo, nodes_[static_cast<size_t>(rr)].hi, ray.t_min, t_best);
    const bool hl = tl != std::numeric_limits<double>::infinity();
    const bool hr = tr != std::numeric_limits<double>::infinity();
    if (hl && hr && sp + 2 <= kStack) {
      // Nearer child on top.
      if (tl <= tr) {
        stack[sp++] = rr;
        stack[sp++] = l;
      } else {
        stack[sp++] = l;
        stack[sp++] = rr;
      }
    } else if (hl && sp < kStack) {
      stack[sp++] = l;
    } else if (hr && sp < kStack) {
      stack[sp++] = rr;
    }
  }
  if (best < 0) return std::nullopt;
  TriangleHit hit;
  hit.triangle = tri_index_[static_cast<size_t>(best)];
  hit.t = t_best;
  hit.barycentric = bary_best;
  const auto& v = tri_pos_[static_cast<size_t>(best)];
  hit.position = bary_best[0] * v[0] + bary_best[1] * v[1] + bary_best[2] * v[2];
  return hit;
}

void TriangleBvh::query_box(const Vec3& lo, const Vec3& hi, std::vector<int32_t>& out) const {
  if (nodes_.empty()) return;
  std::vector<int32_t> stack{0};
  auto overlaps = [&](const Node& n) {
    for (int a = 0; a < 3; ++a) {
      if (n.hi[a] < lo[a] || n.lo[a] > hi[a]) return false;
    }
    return true;
  };
  while (!stack.empty()) {
    const Node& n = nodes_[static_cast<size_t>(stack.back())];
    stack.pop_back();
    if (!overlaps(n)) continue;
    if (n.count > 0) {
      for (int32_t i = n.first; i < n.first + n.count; ++i) {
        Box b;
        for (const Vec3& p : tri_pos_[static_cast<size_t>(i)]) b.grow(p);
        if ((b.hi.array() >= lo.array()).all() && (b.lo.array() <= hi.array()).all()) {
          out.push_back(tri_index_[static_cast<size_t>(i)]);
        }
      }
    } else {
      stack.push_back(n.first);
      stack.push_back(n.first + 1);
    }
  }
}

std::array<Vec3, 2> TriangleBvh::bounds() const {
  if (nodes_.empty()) return {Vec3::Zero(), Vec3::Zero()};
  const Node& n = nodes_[0];
  return {Vec3(n.lo[0], n.lo[1], n.lo[2]), Vec3(n.hi[0], n.hi[1], n.hi[2])};
}

// ------------------------------------------------------------------------------------------------
// RayRefiner

RayRefiner::RayRefiner(LimitEvaluator evaluator) : evaluator_(std::move(evaluator)) {
  const ControlMesh& mesh = evaluator_.mesh();
  const int32_t nf = mesh.num_faces();
  edge_offsets_ = mesh.face_offsets();
  neighbours_.assign(mesh.face_indices().size(), FaceEdge{});
  // Sort the undirected edges; the two faces of an interior edge end up next to each other.
  struct Entry {
    uint64_t key;
    int32_t face, edge;
  };
  std::vector<Entry> entries;
  entries.reserve(mesh.face_indices().size());
  for (int32_t f = 0; f < nf; ++f) {
    const auto verts = mesh.face(f);
    const auto n = static_cast<int32_t>(verts.size());
    for (int32_t i = 0; i < n; ++i) {
      const auto a = static_cast<uint32_t>(verts[static_cast<size_t>(i)]);
      const auto b = static_cast<uint32_t>(verts[static_cast<size_t>((i + 1) % n)]);
      entries.push_back({(static_cast<uint64_t>(std::min(a, b)) << 32) | std::max(a, b), f, i});
    }
  }
  std::sort(entries.begin(), entries.end(), [](const Entry& x, const Entry& y) {
    return x.key != y.key ? x.key < y.key : (x.face != y.face ? x.face < y.face : x.edge < y.edge);
  });
  for (size_t k = 0; k + 1 < entries.size(); ++k) {
    if (entries[k].key != entries[k + 1].key) continue;
    // Manifold meshes (validated by the evaluator) have at most two faces per edge.
    const Entry& x = entries[k];
    const Entry& y = entries[k + 1];
    const auto start_of = [&](const Entry& e) { return mesh.face(e.face)[static_cast<size_t>(e.edge)]; };
    const bool same = start_of(x) == start_of(y);
    neighbours_[static_cast<size_t>(edge_offsets_[static_cast<size_t>(x.face)] + x.edge)] = {y.face, y.edge, same};
    neighbours_[static_cast<size_t>(edge_offsets_[static_cast<size_t>(y.face)] + y.edge)] = {x.face, x.edge, same};
    ++k;
  }
  size_ = std::max(mesh.bounding_diagonal(), std::numeric_limits<double>::min());
}

std::optional<SurfacePoint> RayRefiner::across(const SurfacePoint& p, int edge) const {
  evaluator_.check(p).value();
  if (edge < 0 || edge > 3) fail(ErrorCode::kInvalidArgument, "edge must be 0, 1, 2 or 3");
  const int32_t n = evaluator_.mesh().face_size(p.face);
  // The point as (face edge, position s along it from its first corner).
  int32_t face_edge = 0;
  double s = 0.0;
  if (n == 4) {
    switch (edge) {
      case 0: face_edge = 0; s = p.u; break;
      case 1: face_edge = 1; s = p.v; break;
      case 2: face_edge = 2; s = 1.0 - p.u; break;
      default: face_edge = 3; s = 1.0 - p.v; break;
    }
  } else {
    const int32_t k = p.subface;
    switch (edge) {
      case 0: face_edge = k; s = 0.5 * p.u; break;                         // corner k -> midpoint of edge k
      case 3: face_edge = (k + n - 1) % n; s = 1.0 - 0.5 * p.v; break;     // midpoint of edge k-1 -> corner k
      case 1: return SurfacePoint{p.face, (k + 1) % n, p.v, 1.0};          // interior: edge k's midpoint -> centre
      default: return SurfacePoint{p.face, (k + n - 1) % n, 1.0, p.u};     // interior: edge k-1's midpoint -> centre
    }
  }
  const FaceEdge& nb = neighbours_[static_cast<size_t>(edge_offsets_[static_cast<size_t>(p.face)] + face_edge)];
  if (nb.face < 0 || !evaluator_.has_limit_surface(nb.face)) return std::nullopt;
  const double sg = nb.same_direction ? s : 1.0 - s;
  const int32_t m = evaluator_.mesh().face_size(nb.face);
  if (m == 4) {
    switch (nb.edge) {
      case 0: return SurfacePoint{nb.face, 0, sg, 0.0};
      case 1: return SurfacePoint{nb.face, 0, 1.0, sg};
      case 2: return SurfacePoint{nb.face, 0, 1.0 - sg, 1.0};
      default: return SurfacePoint{nb.face, 0, 0.0, 1.0 - sg};
    }
  }
  if (sg <= 0.5) return SurfacePoint{nb.face, nb.edge, 2.0 * sg, 0.0};
  return SurfacePoint{nb.face, (nb.edge + 1) % m, 0.0, 2.0 * (1.0 - sg)};
}

Result<RayRefinement> RayRefiner::refine(const Ray& ray, const SurfacePoint& start,
                                         const std::vector<Vec3>& control_positions,
                                         const RefineOptions& options) const {
  return capture([&]() -> RayRefinement {
    check_ray(ray).value();
    evaluator_.check(start).value();
    if (control_positions.size() != static_cast<size_t>(evaluator_.num_control_points())) {
      fail(ErrorCode::kInvalidArgument, "expected " + std::to_string(evaluator_.num_control_points()) +
                                            " control positions, got " + std::to_string(control_positions.size()));
    }
    if (options.max_iterations < 0 || options.max_iterations > 1000 || !std::isfinite(options.tolerance) ||
        options.tolerance < 0.0) {
      fail(ErrorCode::kInvalidArgument, "refinement options: max_iterations must be in 0..1000 and tolerance >= 0");
    }

    // Two unit vectors normal to the ray: the residual is the point's offset from the ray's line.
    const Vec3 d = ray.direction.normalized();
    const Vec3 e1 = d.unitOrthogonal();
    const Vec3 e2 = d.cross(e1);

    struct State {
      SurfacePoint p;
      Vec3 x, xu, xv;
      double g1 = 0.0, g2 = 0.0, dist = 0.0;
    };
    LimitStencil st;
    auto evaluate = [&](const SurfacePoint& p) {
      State s;
      s.p = p;
      evaluator_.stencil(p, st);
      s.x = apply_weights(st.indices, st.position, control_positions);
      s.xu = apply_weights(st.indices, st.du, control_positions);
      s.xv = apply_weights(st.indices, st.dv, control_positions);
      if (!finite(s.x) || !finite(s.xu) || !finite(s.xv)) {
        fail(ErrorCode::kInvalidArgument, "the control positions give a non-finite limit surface");
      }
      const Vec3 r = s.x - ray.origin;
      s.g1 = e1.dot(r);
      s.g2 = e2.dot(r);
      s.dist = std::hypot(s.g1, s.g2);
      return s;
    };

    RayRefinement out;
    State cur = evaluate(start);
    // Below this the residual is rounding noise (far-away origins limit the attainable accuracy).
    const double noise = 64.0 * std::numeric_limits<double>::epsilon() * (ray.origin.norm() + cur.x.norm());
    const double tol = std::max(options.tolerance * size_, noise);
    RefineStatus status = RefineStatus::kNotConverged;
    int iterations = 0;
    bool stuck_at_boundary = false;
    constexpr int kMaxCrossings = 32;

    while (true) {
      if (cur.dist <= tol) {
        status = RefineStatus::kConverged;
        break;
      }
      if (iterations >= options.max_iterations || out.face_crossings > kMaxCrossings) break;
      // Newton step on g(u, v) = [e1 . (x - o), e2 . (x - o)].
      const double j11 = e1.dot(cur.xu), j12 = e1.dot(cur.xv), j21 = e2.dot(cur.xu), j22 = e2.dot(cur.xv);
      const double det = j11 * j22 - j12 * j21;
      const double scale = std::max({std::abs(j11), std::abs(j12), std::abs(j21), std::abs(j22)});
      if (!(std::abs(det) > 1e-14 * scale * scale)) break;  // the ray grazes the surface
      const double du = -(j22 * cur.g1 - j12 * cur.g2) / det;
      const double dv = -(-j21 * cur.g1 + j11 * cur.g2) / det;

      bool moved = false;
      for (double alpha = 1.0; alpha > 1e-6 && iterations < options.max_iterations; alpha *= 0.5) {
        double u = cur.p.u + alpha * du, v = cur.p.v + alpha * dv;
        if (u >= 0.0 && u <= 1.0 && v >= 0.0 && v <= 1.0) {
          ++iterations;
          State next = evaluate(SurfacePoint{cur.p.face, cur.p.subface, u, v});
          if (next.dist < cur.dist) {
            cur = next;
            moved = true;
            break;
          }
          continue;  // damp
        }
        // The step leaves the domain: find where, and continue in the neighbour across that side.
        double a_exit = alpha;
        int side = -1;
        auto consider = [&](double start_c, double delta_c, int low_side, int high_side) {
          if (start_c + alpha * delta_c > 1.0) {
            const double a = (1.0 - start_c) / delta_c;
            if (a < a_exit || side < 0) { a_exit = std::max(0.0, a); side = high_side; }
          } else if (start_c + alpha * delta_c < 0.0) {
            const double a = -start_c / delta_c;
            if (a < a_exit || side < 0) { a_exit = std::max(0.0, a); side = low_side; }
          }
        };
        consider(cur.p.u, du, 3, 1);
        consider(cur.p.v, dv, 0, 2);
        SurfacePoint edge_point{cur.p.face, cur.p.subface, std::clamp(cur.p.u + a_exit * du, 0.0, 1.0),
                                std::clamp(cur.p.v + a_exit * dv, 0.0, 1.0)};
        if (side == 0) edge_point.v = 0.0;
        if (side == 1) edge_point.u = 1.0;
        if (side == 2) edge_point.v = 1.0;
        if (side == 3) edge_point.u = 0.0;
        std::optional<SurfacePoint> next_point = across(edge_point, side);
        if (next_point) {
          ++iterations;
          ++out.face_crossings;
          cur = evaluate(*next_point);
          moved = true;
          break;
        }
        // Open boundary (or ghost face): slide along it, the step projected into the domain.
        ++iterations;
        State next = evaluate(SurfacePoint{cur.p.face, cur.p.subface, std::clamp(u, 0.0, 1.0), std::clamp(v, 0.0, 1.0)});
        if (next.dist < cur.dist) {
          cur = next;
          moved = true;
          break;
        }
        stuck_at_boundary = true;
      }
      if (!moved) {
        const bool on_boundary = cur.p.u == 0.0 || cur.p.u == 1.0 || cur.p.v == 0.0 || cur.p.v == 1.0;
        if (stuck_at_boundary && on_boundary) status = RefineStatus::kAtBoundary;
        break;
      }
      stuck_at_boundary = false;
    }
    if (status == RefineStatus::kNotConverged && cur.dist > tol) {
      const bool on_boundary = cur.p.u == 0.0 || cur.p.u == 1.0 || cur.p.v == 0.0 || cur.p.v == 1.0;
      bool open = false;
      if (on_boundary) {
        if (cur.p.v == 0.0) open |= !across(cur.p, 0).has_value();
        if (cur.p.u == 1.0) open |= !across(cur.p, 1).has_value();
        if (cur.p.v == 1.0) open |= !across(cur.p, 2).has_value();
        if (cur.p.u == 0.0) open |= !across(cur.p, 3).has_value();
      }
      if (open) status = RefineStatus::kAtBoundary;
    }

    out.point = cur.p;
    out.position = cur.x;
    out.du = cur.xu;
    out.dv = cur.xv;
    const Vec3 n = cur.xu.cross(cur.xv);
    out.normal = n.norm() > 0.0 ? Vec3(n.normalized()) : Vec3::Zero();
    out.t = (cur.x - ray.origin).dot(ray.direction) / ray.direction.squaredNorm();
    out.distance_to_ray = cur.dist;
    out.status = status;
    out.iterations = iterations;
    return out;
  });
}

// ------------------------------------------------------------------------------------------------
// Picker

Picker::Picker(const Tessellation& tessellation, TriangleBvh bvh, const TriangleBvh::Options& options)
    : tessellation_(&tessellation), options_(options), bvh_(std::move(bvh)), refiner_(tessellation.evaluator()) {}

Result<Picker> Picker::create(const Tessellation& tessellation, const TriangleBvh::Options& options) {
  return capture([&]() -> Picker {
    TriangleBvh bvh = TriangleBvh::build(tessellation.vertices(), tessellation.triangles(), options).value();
    return Picker(tessellation, std::move(bvh), options);
  });
}

Result<std::optional<TriangleHit>> Picker::intersect(const Ray& ray, bool cull_back_faces) const {
  if (auto ok = check_ray(ray); !ok) return ok.error();
  return bvh_.intersect(ray, cull_back_faces);
}

Result<std::optional<Pick>> Picker::pick(const Ray& ray, const PickOptions& options) const {
  return capture([&]() -> std::optional<Pick> {
    check_ray(ray).value();
    std::optional<TriangleHit> hit = bvh_.intersect(ray, options.cull_back_faces);
    if (!hit) return std::nullopt;
    Pick pick;
    pick.hit = *hit;
    pick.estimate = tessellation_->surface_point(hit->triangle, hit->barycentric);
    RefineOptions refine_options = options.refinement;
    if (!options.refine) refine_options.max_iterations = 0;  // evaluate at the estimate only
    const RayRefinement r =
        refiner_.refine(ray, pick.estimate, tessellation_->control_positions(), refine_options).value();
    pick.point = r.point;
    pick.position = r.position;
    pick.du = r.du;
    pick.dv = r.dv;
    pick.normal = r.normal;
    pick.t = r.t;
    pick.distance_to_ray = r.distance_to_ray;
    pick.status = r.status;
    pick.iterations = r.iterations;
    pick.face_crossings = r.face_crossings;
    return pick;
  });
}

Result<void> Picker::refit() { return bvh_.refit(tessellation_->vertices()); }

Result<void> Picker::rebuild() {
  auto bvh = TriangleBvh::build(tessellation_->vertices(), tessellation_->triangles(), options_);
  if (!bvh) return bvh.error();
  bvh_ = std::move(bvh).value();
  return {};
}

}  // namespace softshell
