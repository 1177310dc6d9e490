#pragma once
/// \file
/// \brief Ray picking on the limit surface: a BVH over a tessellation's triangles finds the hit
/// triangle, its quadtree path gives the estimate `(face, subface, u, v)` (paper Section 5.1), and a
/// few Newton steps on the exact limit surface refine it, crossing to neighbouring faces and
/// sub-faces where the iteration leaves the face it started on.
///
/// Units: positions and lengths are in the mesh's length unit; a ray's parameter `t` is in units of
/// its direction's length (the point is `origin + t * direction`).

#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <span>
#include <vector>

#include "softshell/limit_evaluator.h"
#include "softshell/result.h"
#include "softshell/tessellation.h"

namespace softshell {

/// A ray (or segment): the points `origin + t * direction` with `t_min <= t <= t_max`.
struct Ray {
  Vec3 origin = Vec3::Zero();
  Vec3 direction = Vec3::UnitZ();  ///< need not be unit length; finite and non-zero
  double t_min = 0.0;              ///< >= 0 is usual; must not be NaN
  double t_max = std::numeric_limits<double>::infinity();  ///< >= t_min; may be +infinity
};

/// Ok, or kInvalidArgument naming what is wrong with the ray (NaN/infinite origin or direction, a
/// zero direction, NaN limits or t_max < t_min).
Result<void> check_ray(const Ray& ray);

/// The nearest triangle a ray hits.
struct TriangleHit {
  int32_t triangle = -1;                  ///< index into the triangle list
  double t = 0.0;                         ///< ray parameter of the hit
  std::array<double, 3> barycentric{};    ///< weights of the triangle's three vertices (sum 1)
  Vec3 position = Vec3::Zero();           ///< the hit point on the triangle
};

/// A bounding volume hierarchy over triangles: binned surface-area-heuristic build, nearest-hit
/// traversal with a watertight ray-triangle test (Woop, Benthin, Wald 2013), so a ray through a
/// shared edge or vertex hits one of the triangles there. `refit` updates the boxes after the
/// vertices moved (same triangles), which keeps the tree valid but may make it slower for large
/// deformations; rebuild then.
///
/// Thread-safety: const member functions may be called concurrently; `refit` may not run at the
/// same time as anything else.
class TriangleBvh {
 public:
  struct Options {
    int max_leaf_size = 4;  ///< triangles per leaf, 1..32
    int bins = 16;          ///< SAH bins per axis, 2..64
  };
  struct Stats {
    int32_t nodes = 0;
    int32_t leaves = 0;
    int32_t depth = 0;
    double build_ms = 0.0;  ///< wall time of the last build
    double refit_ms = 0.0;  ///< wall time of the last refit
  };

  TriangleBvh();
  /// Builds over `vertices` (#V) and `triangles` (#T, indices into `vertices`). Copies what it
  /// needs. kInvalidArgument for an index out of range, a non-finite vertex or bad options.
  static Result<TriangleBvh> build(std::span<const Vec3> vertices, std::span<const std::array<int32_t, 3>> triangles,
                                   const Options& options);
  static Result<TriangleBvh> build(std::span<const Vec3> vertices, std::span<const std::array<int32_t, 3>> triangles) {
    return build(vertices, triangles, Options{});
  }

  /// Moves the triangles to new vertex positions (same count and order as in `build`).
  /// kInvalidArgument for a wrong count or a non-finite vertex (the tree is then left unchanged).
  Result<void> refit(std::span<const Vec3> vertices);

  /// The nearest hit with t in [t_min, t_max], or std::nullopt for a miss. Both sides of a triangle
  /// count unless `cull_back_faces` (then only triangles whose counter-clockwise side faces the
  /// ray's origin). The ray must pass `check_ray` (not re-checked here; a bad ray gives a miss).
  std::optional<TriangleHit> intersect(const Ray& ray, bool cull_back_faces = false) const;

  /// Every triangle whose bounding box overlaps the box [lo, hi] (appended to `out`).
  void query_box(const Vec3& lo, const Vec3& hi, std::vector<int32_t>& out) const;

  int32_t num_triangles() const { return static_cast<int32_t>(tri_index_.size()); }
  const Stats& stats() const { return stats_; }
  /// Bounds of all triangles (lo, hi); zero for an empty tree.
  std::array<Vec3, 2> bounds() const;

 private:
  struct Node {
    double lo[3];
    double hi[3];
    int32_t first;  // leaf: first entry in tri_index_; inner: index of the left child (right = first + 1)
    int32_t count;  // leaf: number of triangles (> 0); inner: 0
  };
  void refit_nodes();

  std::vector<Node> nodes_;
  std::vector<int32_t> tri_index_;               // triangle ids in leaf order
  std::vector<std::array<int32_t, 3>> tri_verts_;  // vertex indices in leaf order
  std::vector<std::array<Vec3, 3>> tri_pos_;     // vertex positions in leaf order (for cache locality)
  size_t num_vertices_ = 0;
  Stats stats_;
};

/// How a limit-surface refinement ended.
enum class RefineStatus : uint8_t {
  kConverged,     ///< the point lies on the ray within the tolerance
  kAtBoundary,    ///< the ray passes just outside an open boundary (or into a ghost face) of the
                  ///< limit surface; the point is the nearest boundary point found, `distance_to_ray` > 0
  kNotConverged,  ///< Newton did not reach the tolerance (ray nearly tangent, iteration limit); the
                  ///< best point found is reported
};

/// Options of the Newton refinement.
struct RefineOptions {
  int max_iterations = 24;   ///< Newton steps (each is one stencil evaluation), including face crossings
  double tolerance = 1e-12;  ///< stop when the distance to the ray is below tolerance * object size
};

/// A point of the limit surface found on (or as near as possible to) a ray.
struct RayRefinement {
  SurfacePoint point;                ///< on the limit surface
  Vec3 position = Vec3::Zero();      ///< limit position at `point` (for the control positions used)
  Vec3 du = Vec3::Zero(), dv = Vec3::Zero();  ///< limit tangents there (w.r.t. the sub-face's u, v)
  Vec3 normal = Vec3::Zero();        ///< unit normal du x dv
  double t = 0.0;                    ///< ray parameter of the point's projection onto the ray
  double distance_to_ray = 0.0;      ///< distance from `position` to the ray's line
  RefineStatus status = RefineStatus::kNotConverged;
  int iterations = 0;                ///< Newton steps taken
  int face_crossings = 0;            ///< times the iteration moved to a neighbouring face or sub-face
};

/// Intersects rays with the exact limit surface by Newton's method on (u, v) (the ray parameter is
/// eliminated by projecting onto the plane normal to the ray), starting from an estimate.
///
/// Where a step leaves the (sub-)face's [0, 1]² the point moves onto the shared edge of the
/// neighbouring face or sub-face (in that face's own coordinates) and the iteration continues
/// there; at an open boundary or a ghost face it stays on the edge (`kAtBoundary` if it cannot get
/// closer). Holds the face adjacency of the evaluator's mesh (built once, O(#faces)).
///
/// Thread-safety: `refine` is const and may be called concurrently.
class RayRefiner {
 public:
  explicit RayRefiner(LimitEvaluator evaluator);

  /// Refines `start` for the surface of `control_positions` (#V; the deformed control points, or
  /// the rest positions). kInvalidArgument for a bad ray, a bad start point, a wrong number of
  /// positions or bad options.
  Result<RayRefinement> refine(const Ray& ray, const SurfacePoint& start, const std::vector<Vec3>& control_positions,
                               const RefineOptions& options) const;
  Result<RayRefinement> refine(const Ray& ray, const SurfacePoint& start,
                               const std::vector<Vec3>& control_positions) const {
    return refine(ray, start, control_positions, RefineOptions{});
  }

  /// The point across the edge of the (sub-)face domain on which `p` lies (u or v equal to 0 or 1),
  /// in the neighbouring face's or sub-face's coordinates: the same limit point. `edge` is the side
  /// of p's domain: 0 = (v = 0), 1 = (u = 1), 2 = (v = 1), 3 = (u = 0). std::nullopt at an open
  /// boundary or next to a ghost face. Throws kInvalidArgument for a bad point or edge.
  std::optional<SurfacePoint> across(const SurfacePoint& p, int edge) const;

  const LimitEvaluator& evaluator() const { return evaluator_; }

 private:
  struct FaceEdge {
    int32_t face = -1;   // neighbour, -1 at a boundary
    int32_t edge = -1;   // its local edge index
    bool same_direction = false;  // the neighbour's edge runs the same way (only on non-oriented input)
  };
  LimitEvaluator evaluator_;
  std::vector<int32_t> edge_offsets_;  // per face, into neighbours_
  std::vector<FaceEdge> neighbours_;   // per face edge i (corner i -> i + 1)
  double size_ = 1.0;                  // bounding diagonal of the rest mesh
};

/// Options of `Picker::pick`.
struct PickOptions {
  /// Run the Newton refinement. Off: `point` = `estimate`, evaluated on the limit surface, and
  /// `status` is kConverged only if that point happens to lie on the ray.
  bool refine = true;
  bool cull_back_faces = false;  ///< ignore triangles seen from behind
  RefineOptions refinement;
};

/// A picked point.
struct Pick {
  // The tessellation hit (paper Section 5.1).
  TriangleHit hit;            ///< triangle, ray parameter, barycentric weights, point on the triangle
  SurfacePoint estimate;      ///< (face, subface, u, v) interpolated from the quad's quadtree path
  // The refined point on the limit surface (equals the estimate when refinement is off).
  SurfacePoint point;
  Vec3 position = Vec3::Zero();  ///< limit position at `point` (current control positions)
  Vec3 du = Vec3::Zero(), dv = Vec3::Zero();  ///< limit tangents there
  Vec3 normal = Vec3::Zero();    ///< unit limit normal there
  double t = 0.0;                ///< ray parameter of `position`'s projection onto the ray
  double distance_to_ray = 0.0;  ///< distance from `position` to the ray's line
  RefineStatus status = RefineStatus::kNotConverged;  ///< kConverged when refined successfully
  int iterations = 0;
  int face_crossings = 0;
};

/// Picks points of a tessellated limit surface with rays.
///
/// Holds a reference to the `Tessellation` (which must outlive the picker and keep its triangles)
/// and a BVH over its triangles. After `Tessellation::update` (a deformation arrived) call `refit`:
/// it refits the BVH to the moved triangles and refines picks on the deformed limit surface (the
/// tessellation's `control_positions()`).
///
/// Thread-safety: `pick` and `intersect` are const and may run concurrently; `refit` may not run
/// at the same time as them (nor may `Tessellation::update`).
class Picker {
 public:
  static Result<Picker> create(const Tessellation& tessellation, const TriangleBvh::Options& options);
  static Result<Picker> create(const Tessellation& tessellation) { return create(tessellation, TriangleBvh::Options{}); }

  /// The nearest pick along the ray, std::nullopt for a miss, kInvalidArgument for a bad ray or
  /// bad options. A refinement that does not converge is still a hit (see `Pick::status`).
  Result<std::optional<Pick>> pick(const Ray& ray, const PickOptions& options) const;
  Result<std::optional<Pick>> pick(const Ray& ray) const { return pick(ray, PickOptions{}); }

  /// Only the triangle hit (no mapping, no refinement): the fast path for collision queries.
  Result<std::optional<TriangleHit>> intersect(const Ray& ray, bool cull_back_faces = false) const;

  /// Follows the tessellation after `Tessellation::update`. kInvalidArgument if its vertex count
  /// changed or a vertex is not finite.
  Result<void> refit();
  /// Rebuilds the BVH over the tessellation's current vertices: slower than `refit` (tens of ms
  /// for 100k triangles) but keeps queries fast after large deformations.
  Result<void> rebuild();

  const Tessellation& tessellation() const { return *tessellation_; }
  const TriangleBvh& bvh() const { return bvh_; }
  const RayRefiner& refiner() const { return refiner_; }

 private:
  Picker(const Tessellation& tessellation, TriangleBvh bvh, const TriangleBvh::Options& options);
  const Tessellation* tessellation_;
  TriangleBvh::Options options_;
  TriangleBvh bvh_;
  RayRefiner refiner_;
};

}  // namespace softshell
