#pragma once
/// \file
/// \brief `Tessellation`: the limit surface as triangles for rendering, picking and collision,
/// where every rendered quad remembers its root face and quadtree path (paper Section 5.1).

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "softshell/limit_evaluator.h"
#include "softshell/result.h"

namespace softshell {

/// A rectangle of a (sub-)face's (u, v) domain.
struct ParamRect {
  double u0 = 0.0, v0 = 0.0, u1 = 1.0, v1 = 1.0;
  bool operator==(const ParamRect&) const = default;
};

/// The quadtree path of a refined quad: at each level the corner (quadrant) of its parent's (u, v)
/// domain it lies in, 0 = (0,0), 1 = (1,0), 2 = (1,1), 3 = (0,1), two bits a level, the first
/// level in the lowest bits. For faces with n != 4 corners the first refinement picks the
/// sub-face, which is stored separately; the path starts at the second level.
struct QuadtreePath {
  uint64_t bits = 0;  ///< 2 bits per level, level 1 in bits 0-1
  uint8_t depth = 0;  ///< number of levels (<= 32)

  /// Corner taken at level `i` (0-based).
  int corner(int i) const { return static_cast<int>((bits >> (2 * i)) & 3u); }
  /// Path with `corner` appended as the next level.
  QuadtreePath child(int corner) const;
  /// The part of the (sub-)face domain this path covers; e.g. [2, 1] -> u in [0.75, 1], v in [0.5, 0.75].
  ParamRect range() const;
  /// From a list of corners, first level first.
  static QuadtreePath from_corners(const std::vector<int>& corners);
  bool operator==(const QuadtreePath&) const = default;
};

/// Uniform refinement of a control mesh to level L (OpenSubdiv Far), with the refined vertices
/// moved to the limit surface (Bfr, the same evaluation the simulation uses) and every refined
/// quad split into two triangles.
///
/// Triangle `t` belongs to quad `t / 2`. Every quad knows its root face, sub-face and quadtree
/// path, so a point on a triangle maps back to `(face, subface, u, v)` (`surface_point`).
///
/// Thread-safety: const member functions may be called concurrently; `update` may not.
class Tessellation {
 public:
  /// One refined quad.
  struct Quad {
    int32_t root_face = 0;             ///< control face it comes from
    int32_t subface = 0;               ///< sub-face of the root face (0 for quads)
    QuadtreePath path;                 ///< its place inside the (sub-)face
    uint8_t rotation = 0;              ///< vertex i sits at corner (i + rotation) % 4 of path.range()
    std::array<int32_t, 4> vertices{};  ///< indices into vertices(), counter-clockwise
  };

  /// Tessellates `evaluator`'s limit surface at `level` (0..8). Ghost faces are left out.
  /// Returns kInvalidArgument for a level out of range, kResourceExhausted if the result would have
  /// more than `max_triangles` triangles.
  static Result<Tessellation> create(const LimitEvaluator& evaluator, int level,
                                     int64_t max_triangles = 50'000'000);

  Tessellation(Tessellation&&) noexcept;
  Tessellation& operator=(Tessellation&&) noexcept;
  ~Tessellation();

  int level() const { return level_; }
  /// Limit positions of the refined vertices (current deformation; see `update`).
  const std::vector<Vec3>& vertices() const { return vertices_; }
  /// Unit limit normals at the refined vertices.
  const std::vector<Vec3>& normals() const { return normals_; }
  /// Triangles, counter-clockwise seen from the normal side; triangle t is half of quad t / 2.
  const std::vector<std::array<int32_t, 3>>& triangles() const { return triangles_; }
  const std::vector<Quad>& quads() const { return quads_; }
  /// The surface point of each refined vertex (one of them where a vertex is shared).
  const std::vector<SurfacePoint>& vertex_points() const { return vertex_points_; }

  /// (u, v) of a quad's four vertices in its (sub-)face's domain.
  std::array<std::array<double, 2>, 4> quad_corner_params(int32_t quad) const;

  /// Maps a point of triangle `t` given by barycentric weights of its three vertices (summing to 1)
  /// to the surface point it approximates (paper Section 5.1): linear interpolation of the
  /// triangle's corner parameters. Throws `Exception(kInvalidArgument)` for a bad triangle index.
  SurfacePoint surface_point(int32_t triangle, const std::array<double, 3>& barycentric) const;

  /// Maximum distance between the triangles and the limit surface of the rest shape, estimated on
  /// a barycentric grid of 28 points per triangle mapped through `surface_point` (the
  /// tessellation's chordal error). Computed on first use and cached. It falls by about 4x a level
  /// on regular faces; next to extraordinary vertices and creases, where the Catmull-Clark
  /// parameterization is not smooth, it falls more slowly.
  double chordal_error() const;

  /// Moves the vertices to the limit surface of the deformed control points `positions` (#V) and
  /// recomputes the normals. The first call builds sparse limit-stencil matrices (cached).
  void update(const std::vector<Vec3>& positions);

  /// The sparse matrix S (#vertices x #control points) with vertices = S * control positions.
  const Eigen::SparseMatrix<double, Eigen::RowMajor>& limit_matrix() const;

  /// The evaluator this tessellation was built from (shares its immutable data).
  const LimitEvaluator& evaluator() const { return *evaluator_; }
  /// The control positions (#V) `vertices()` currently show: the mesh's rest positions after
  /// `create`, the argument of the last `update` afterwards.
  const std::vector<Vec3>& control_positions() const { return control_positions_; }

 private:
  struct Lazy;  // caches built on first use (chordal error, limit matrices), guarded by a mutex
  Tessellation();

  std::optional<LimitEvaluator> evaluator_;  // shares the evaluator's immutable data
  int level_ = 0;
  std::vector<Vec3> vertices_;
  std::vector<Vec3> normals_;
  std::vector<std::array<int32_t, 3>> triangles_;
  std::vector<Quad> quads_;
  std::vector<SurfacePoint> vertex_points_;
  std::vector<Vec3> control_positions_;
  std::unique_ptr<Lazy> lazy_;
};

}  // namespace softshell
