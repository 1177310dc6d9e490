#pragma once
/// \file
/// \brief `LimitEvaluator`: exact evaluation of the Catmull-Clark limit surface and of its basis
/// functions (limit stencils), at every point including extraordinary vertices.

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "softshell/control_mesh.h"
#include "softshell/result.h"

namespace softshell {

/// A point of the limit surface (PROTOCOL.md, Conventions): a control face, a sub-face and (u, v).
///
/// Quad faces have one sub-face (0): corner 0 of the face is (0,0), corner 1 (1,0), corner 2 (1,1),
/// corner 3 (0,1). A face with n != 4 corners has n sub-faces: sub-face k is the quad at corner k
/// with (0,0) at corner k, (1,0) at the midpoint of edge k -> k+1, (1,1) at the face centre and
/// (0,1) at the midpoint of edge k-1 -> k (Ptex / Bfr normalized sub-face coordinates).
struct SurfacePoint {
  int32_t face = 0;
  int32_t subface = 0;
  double u = 0.0;  ///< in [0, 1]
  double v = 0.0;  ///< in [0, 1]
  bool operator==(const SurfacePoint&) const = default;
};

/// The limit surface at a point as a linear combination of control points: for control point
/// `indices[k]`, `position[k]` is the weight of the limit position, `du[k]`/`dv[k]` of the first
/// derivatives and `duu[k]`, `duv[k]`, `dvv[k]` of the second derivatives, with respect to the
/// (sub-)face's own u and v. Position weights sum to 1, derivative weights to 0.
struct LimitStencil {
  std::vector<int32_t> indices;
  std::vector<double> position, du, dv, duu, duv, dvv;
  size_t size() const { return indices.size(); }
};

/// Limit position, derivatives and unit normal at a point.
struct LimitSample {
  Vec3 position = Vec3::Zero();
  Vec3 du = Vec3::Zero(), dv = Vec3::Zero();
  Vec3 duu = Vec3::Zero(), duv = Vec3::Zero(), dvv = Vec3::Zero();
  /// Unit normal du x dv / |du x dv| (zero where the tangents are parallel).
  Vec3 normal() const;
};

/// Evaluates the Catmull-Clark limit surface of a control mesh (PROTOCOL.md scheme: Catmull-Clark,
/// boundary interpolation from the mesh's `BoundaryMode`, creases and corners from its tags).
///
/// Built once per mesh topology; evaluation is then cheap. The evaluation is exact everywhere:
/// regular faces are bicubic B-spline patches (OpenSubdiv Bfr); every other face (at an
/// extraordinary vertex, an n-gon, a quad next to a non-quad) is split by OpenSubdiv's
/// refinement into bicubic pieces and, at each extraordinary vertex, into rings of bicubic
/// pieces that shrink toward it, evaluated with the powers of the local subdivision matrix
/// (Stam's exact evaluation). Derivative weights are the exact derivatives of the position
/// weights at every (u, v), arbitrarily close to an extraordinary vertex. (Faces at a
/// non-manifold vertex or at an inner vertex of only two faces, where the scheme has no tangent
/// plane modes of its own, are Bfr's approximation instead.)
///
/// At an extraordinary vertex itself (the corner of a face or sub-face where it sits) the
/// derivatives with respect to the face's (u, v) vanish (valence 3) or diverge (valence 5 and
/// more). There the stencil gives the exact limit position (the same as OpenSubdiv's limit
/// mask), for du and dv two vectors that span the exact tangent plane with du x dv along the
/// surface normal (inside the mesh: OpenSubdiv's limit tangent masks rotated onto the face's two
/// edges at that corner; on the boundary: the two dominant left eigenvectors of the local
/// subdivision matrix), and zero second derivatives. The normal is exact there; the lengths of
/// du and dv, and curvatures, are not derivatives. The same holds closer than 2^-1000 to such a
/// vertex.
///
/// Copies are cheap and share the same immutable evaluator.
/// Thread-safety: all const member functions may be called concurrently.
class LimitEvaluator {
 public:
  struct Options {
    /// Bfr refinement levels around extraordinary vertices, with `sharp_features` on a tagged
    /// mesh only (the smooth surface is evaluated exactly and ignores this). Range 1..10.
    int approx_level_smooth = 3;
    /// Bfr refinement levels around sharp features, with `sharp_features` only (OpenSubdiv
    /// default 6). Range 1..10.
    int approx_level_sharp = 6;
    /// Let the mesh's crease and corner tags shape the surface. Off by default: the simulation
    /// uses the smooth limit surface (a sharp kink would act as a hinge in a Kirchhoff-Love shell),
    /// and a client must evaluate, render and pick on the same surface the server simulates, or
    /// a (face, u, v) would name different points. Turn it on only to display tagged meshes
    /// that are not simulated. On a tagged mesh the surface is then OpenSubdiv Bfr's, which
    /// approximates it next to extraordinary vertices and semi-sharp features (Gregory patches
    /// `approx_level_*` levels deep); the `ev_corner_*` functions answer false.
    bool sharp_features = false;
  };

  /// Builds the evaluator. The mesh must pass `validate_mesh()`; otherwise its first issue is
  /// returned. Copies the mesh (without its crease and corner tags unless
  /// `options.sharp_features`): `mesh()` is the mesh as evaluated.
  static Result<LimitEvaluator> create(const ControlMesh& mesh, const Options& options);
  static Result<LimitEvaluator> create(const ControlMesh& mesh) { return create(mesh, Options{}); }

  LimitEvaluator(const LimitEvaluator&) = default;
  LimitEvaluator& operator=(const LimitEvaluator&) = default;
  LimitEvaluator(LimitEvaluator&&) noexcept = default;
  LimitEvaluator& operator=(LimitEvaluator&&) noexcept = default;
  ~LimitEvaluator();

  const ControlMesh& mesh() const;
  const Options& options() const;
  int32_t num_faces() const;
  int32_t num_control_points() const;

  /// Number of sub-faces of face `f`: 1 for a quad, n for an n-gon.
  int32_t num_subfaces(int32_t face) const;
  /// True if face `f` has a limit surface. False only for ghost faces (BoundaryMode::kNone faces
  /// that touch the boundary).
  bool has_limit_surface(int32_t face) const;
  /// True if face `f` is a regular bicubic B-spline patch (no extraordinary vertex, no sharpness).
  bool is_regular(int32_t face) const;
  /// Maximum number of control points any face's stencil uses.
  int32_t max_stencil_size() const;

  /// Ok, or kInvalidArgument saying what is wrong with `p` (face or sub-face out of range, u or v
  /// outside [0, 1] or not finite, a ghost face).
  Result<void> check(const SurfacePoint& p) const;

  /// The limit stencil at `p`. Throws `Exception(kInvalidArgument)` if `check(p)` fails.
  LimitStencil stencil(const SurfacePoint& p) const;
  /// Same, reusing `out`'s storage (no allocation once it has grown).
  void stencil(const SurfacePoint& p, LimitStencil& out) const;

  /// Stencils of many points of one (sub-)face, setting the face up once (what the simulation's
  /// quadrature uses). `out_weights` is (6 * uvs.size()) x support(face).size(): rows 6i .. 6i+5
  /// are the weights of N, N,u, N,v, N,uu, N,uv, N,vv at point i, columns follow `out_indices`.
  /// Throws `Exception(kInvalidArgument)` for a bad face, sub-face or (u, v).
  void face_stencils(int32_t face, int32_t subface, const std::vector<std::array<double, 2>>& uvs,
                     std::vector<int32_t>& out_indices, Eigen::MatrixXd& out_weights) const;

  /// Quadrature at an extraordinary vertex (EV). A square cell of side `cell_size` at corner
  /// `corner` (0 = (0,0), 1 = (1,0), 2 = (1,1), 3 = (0,1)) of a (sub-)face's domain where an EV
  /// sits holds infinitely many polynomial rings shrinking toward it, on which a Gauss rule is not
  /// exact. Fills `weight_factors` (gauss_points^2 values; value i + gauss_points j belongs to the
  /// point (u0 + h x_i, v0 + h x_j) of the cell, x the Gauss-Legendre points on [0, 1]) with factors
  /// for the weights of the gauss_points x gauss_points Gauss-Legendre rule on the cell that make
  /// it exact for the leading terms of the surface's expansion at the vertex: the Jacobians of
  /// every pair of the dominant eigenmodes of the local subdivision matrix, which are the leading
  /// parts of the area element and of the surface gradient of every basis function there.
  /// Returns false (and leaves `weight_factors` alone) if that corner is not an EV of an exactly
  /// evaluated face, or if the cell is larger than the region where the expansion holds.
  bool ev_corner_weights(int32_t face, int32_t subface, int corner, double cell_size, int gauss_points,
                         std::vector<double>& weight_factors) const;

  /// For the same cells as ev_corner_weights: the exact integral over the cell of
  /// N_A (x_u x x_v) du dv for the control positions given (#V), column k for control point
  /// support(face)[k] (the load of a unit pressure, which near the vertex no point rule integrates
  /// exactly). False as for ev_corner_weights.
  bool ev_corner_normal_weights(int32_t face, int32_t subface, int corner, double cell_size,
                                const std::vector<Vec3>& positions, Eigen::Matrix3Xd& out) const;

  /// Control point indices of face `f`'s stencil (the same for every point of the face).
  std::vector<int32_t> support(int32_t face) const;

  /// Limit position and derivatives at `p` for the rest positions or for `positions` (#V).
  LimitSample evaluate(const SurfacePoint& p) const;
  LimitSample evaluate(const SurfacePoint& p, const std::vector<Vec3>& positions) const;

 private:
  friend class Tessellation;  // shares the OpenSubdiv objects
  struct Impl;
  explicit LimitEvaluator(std::shared_ptr<const Impl> impl);
  std::shared_ptr<const Impl> impl_;
};

/// Applies stencil weights to control-point values: sum_k weights[k] * values[indices[k]].
Vec3 apply_weights(const std::vector<int32_t>& indices, const std::vector<double>& weights,
                   const std::vector<Vec3>& values);

}  // namespace softshell
