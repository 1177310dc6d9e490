#pragma once
/// \file
/// \brief `LimitEvaluator`: exact evaluation of the Catmull-Clark limit surface and of its basis
/// functions (limit stencils) with OpenSubdiv Bfr.

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
/// Built once per mesh topology; evaluation is then cheap. Regular faces are exact bicubic
/// B-spline patches. Faces next to an extraordinary vertex are approximated by OpenSubdiv Bfr's
/// patch tree refined `approx_level_smooth` levels toward it (Options below).
///
/// Copies are cheap and share the same immutable evaluator.
/// Thread-safety: all const member functions may be called concurrently.
class LimitEvaluator {
 public:
  struct Options {
    /// Bfr refinement levels around extraordinary vertices of smooth faces (OpenSubdiv's default
    /// is 2; softshell uses 3, which brings the shell's compliance within ~2e-5 of the exact limit
    /// surface's, see README "Quadrature"). Clients and server must use the same value so that a
    /// (face, u, v) names the same point on both. Range 1..10.
    int approx_level_smooth = 3;
    /// Bfr refinement levels around sharp features (OpenSubdiv default 6). Range 1..10.
    int approx_level_sharp = 6;
    /// Let the mesh's crease and corner tags shape the surface. Off by default: the simulation
    /// uses the smooth limit surface (a sharp kink would act as a hinge in a Kirchhoff-Love shell),
    /// and a client must evaluate, render and pick on the same surface the server simulates, or
    /// a (face, u, v) would name different points. Turn it on only to display tagged meshes
    /// that are not simulated.
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
