#pragma once
/// \file
/// \brief Levels of detail (paper Section 5.2): a control mesh refined k levels by Catmull-Clark
/// (the same limit surface with 4^k times more control points), the refinement matrix S with
/// x_fine = S x_coarse, and the transfer of constraints and forces from the coarse to the fine mesh
/// (and of forces back). `ParallelLevels` runs the paper's "parallel simulation" over a `Session`.
///
/// Units: as the mesh (positions in its length unit, forces in N when SI).

#include <chrono>
#include <cstdint>
#include <future>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/SparseCore>

#include "softshell/control_mesh.h"
#include "softshell/deformation.h"
#include "softshell/limit_evaluator.h"
#include "softshell/material.h"
#include "softshell/result.h"
#include "softshell/session.h"

namespace softshell {

/// How forces on coarse control points become forces on fine control points. Both keep the total
/// force exactly (the rows of S sum to 1).
enum class ForceTransfer : uint8_t {
  /// f_f = S D⁻¹ f_c with D = diag(column sums of S): the force is subdivided like the positions
  /// (paper Section 5.2), onto the coarse point's fine counterpart and its neighbourhood, scaled
  /// so that it adds up to the coarse force. Local (the coarse point's support on the fine mesh).
  kSubdivide,
  /// f_f = S (SᵀS)⁻¹ f_c: the least-squares fine forces whose coarse equivalent Sᵀ f_f is exactly
  /// f_c, so that the virtual work f_fᵀ (S u_c) = f_cᵀ u_c of every coarse displacement is kept.
  /// Global support (the weights decay quickly away from the force); one sparse factorization of
  /// SᵀS on first use.
  kVirtualWork,
};

/// A control mesh refined `levels` times with OpenSubdiv Far (uniform Catmull-Clark, the coarse
/// mesh's boundary mode, creases and corners carried with their sharpness decreased per level), so
/// both meshes have the same limit surface.
///
/// Correspondences:
///  - control points: coarse point i is fine point i (OpenSubdiv numbers the children of vertices
///    first; checked when the refinement is built); its fine position is S x_c, not x_c;
///  - faces: coarse face F (sub-face k) covers 4^levels (4^(levels-1) per sub-face) fine quads;
///    `fine_point` / `coarse_point` map a surface point between the levels exactly.
///
/// With BoundaryMode::kNone only the fine faces that touch the boundary are ghosts, so the fine
/// limit surface also covers the inner part of the coarse ghost ring (the coarse surface is the
/// same part of it as before).
///
/// Immutable after `create`. Thread-safety: every member function may be called concurrently.
class MeshRefinement {
 public:
  /// Refines `coarse` (which must pass `validate_mesh`) `levels` times, 1..6. kInvalidArgument for
  /// a bad level, kResourceExhausted if the fine mesh would have more than `max_fine_vertices`.
  /// `sharp_features` as in `LimitEvaluator::Options`: off (the default), crease and corner tags
  /// are ignored, so the fine mesh has the smooth limit surface the evaluator and the simulation
  /// use; on, they shape the refinement and are carried to the fine mesh.
  static Result<MeshRefinement> create(const ControlMesh& coarse, int levels, int64_t max_fine_vertices = 20'000'000,
                                       bool sharp_features = false);

  MeshRefinement(MeshRefinement&&) noexcept;
  MeshRefinement& operator=(MeshRefinement&&) noexcept;
  ~MeshRefinement();

  int levels() const;
  const ControlMesh& coarse() const;
  /// The refined mesh: every face a quad, positions S x_c, same boundary mode, carried tags.
  const ControlMesh& fine() const;

  /// S, #fine vertices x #coarse vertices, rows sum to 1: x_f = S x_c for every coarse shape
  /// (deformed ones too: S maps coarse displacements to fine displacements that give the same
  /// limit surface).
  const Eigen::SparseMatrix<double, Eigen::RowMajor>& matrix() const;

  /// S x_c for coarse positions (#coarse vertices), e.g. a coarse deformation result.
  /// kInvalidArgument on a wrong count.
  Result<std::vector<Vec3>> refine_positions(const std::vector<Vec3>& coarse_positions) const;

  /// Evaluator options for the fine mesh. The smooth limit surface is evaluated exactly, so both
  /// levels' surfaces agree to rounding with any options; with `sharp_features`, Bfr's
  /// approximation next to sharp features is kept over the same regions on both levels
  /// (approximation levels lowered by `levels()`, at least 1).
  LimitEvaluator::Options fine_evaluator_options(const LimitEvaluator::Options& coarse_options) const;

  /// The fine surface point (a quad face, sub-face 0) that is the same limit point as `coarse_point`.
  /// kInvalidArgument for a point outside the coarse mesh's faces / sub-faces / [0, 1]².
  Result<SurfacePoint> fine_point(const SurfacePoint& coarse_point) const;
  /// The inverse: the coarse (face, sub-face, u, v) of a fine surface point.
  Result<SurfacePoint> coarse_point(const SurfacePoint& fine_point) const;

  /// Vertex constraints carried to the corresponding fine control points (same index, mask and
  /// displacement). This is the paper's approximation (Fig. 5): the fine mesh moves its
  /// neighbourhood the same way; the limit surface follows only approximately. Use limit
  /// constraints where the limit surface must move exactly. kInvalidArgument for bad indices.
  Result<std::vector<VertexConstraint>> vertex_constraints_to_fine(const std::vector<VertexConstraint>& coarse) const;

  /// A limit constraint at the same limit point on the fine mesh (exact: same target).
  Result<LimitConstraint> limit_constraint_to_fine(const LimitConstraint& coarse) const;

  /// Coarse point forces to fine point forces (see `ForceTransfer`); the total force is kept
  /// exactly. Output: one force per fine control point that receives one, ascending index.
  Result<std::vector<PointForce>> forces_to_fine(const std::vector<PointForce>& coarse,
                                                 ForceTransfer transfer = ForceTransfer::kSubdivide) const;
  /// Fine point forces to their coarse equivalent f_c = Sᵀ f_f (virtual work and total force kept
  /// exactly). Output ascending by index.
  Result<std::vector<PointForce>> forces_to_coarse(const std::vector<PointForce>& fine) const;

  /// A whole request given on the coarse mesh, for the fine mesh: vertex constraints by
  /// correspondence, limit constraints and surface forces at the same limit points, point forces
  /// by `transfer`, surface load and pressure unchanged. Lagrange constraints are carried by the
  /// control point correspondence, like vertex constraints (approximate unless the coefficients
  /// came from something that is the same on both levels; build limit constraints instead).
  Result<DeformationRequest> request_to_fine(const DeformationRequest& coarse,
                                             ForceTransfer transfer = ForceTransfer::kSubdivide) const;

 private:
  struct Impl;
  MeshRefinement();
  std::unique_ptr<Impl> impl_;
};

/// One delivered result of `ParallelLevels`.
struct LevelResult {
  uint64_t submission = 0;   ///< the value `submit` returned
  bool fine = false;         ///< false: the coarse level's result; true: the fine level's
  /// The deformation (positions of that level's control points) or why it failed.
  Result<DeformationResult> result = Error{ErrorCode::kInternal, "no result"};
};

/// The paper's parallel simulation (Section 5.2) over any `Session`: the coarse mesh and its
/// refinement are two geometries on the server; every interaction, given for the coarse mesh, is
/// sent to both at once (`deform_async`, never blocking); the coarse result (fast) is delivered
/// first and the fine (accurate) one when it is ready.
///
/// Delivery order: results are keyed (submission, level) and only a key newer than the last one
/// delivered is ever delivered, so a slow fine result of an older interaction never replaces a
/// newer coarse one; superseded results are dropped. `poll` never blocks.
///
/// The session must outlive this object. The destructor waits for requests still in flight.
/// Thread-safety: all member functions may be called from several threads.
class ParallelLevels {
 public:
  /// Refines `coarse` `levels` times and uploads both meshes with `material` into `name_space`.
  static Result<std::unique_ptr<ParallelLevels>> create(Session& session, const ControlMesh& coarse,
                                                        const Material& material, int levels,
                                                        std::string_view name_space = "",
                                                        ForceTransfer transfer = ForceTransfer::kSubdivide);
  ~ParallelLevels();
  ParallelLevels(const ParallelLevels&) = delete;
  ParallelLevels& operator=(const ParallelLevels&) = delete;

  const MeshRefinement& refinement() const { return refinement_; }
  const GeomId& coarse_id() const { return coarse_id_; }
  const GeomId& fine_id() const { return fine_id_; }

  /// Sends `coarse_request` (for the coarse mesh) to the coarse geometry and its transfer to the
  /// fine geometry. Returns the submission number (1, 2, ...). kInvalidArgument if the request
  /// does not fit the coarse mesh (nothing is sent then).
  Result<uint64_t> submit(const DeformationRequest& coarse_request);

  /// The next result to show, if one is ready (never blocks).
  std::optional<LevelResult> poll();
  /// Waits up to `timeout` for the next result to show.
  std::optional<LevelResult> wait(std::chrono::milliseconds timeout);

  /// Requests sent and not yet delivered or dropped.
  size_t in_flight() const;

 private:
  struct Pending {
    uint64_t submission;
    bool fine;
    std::shared_future<Result<DeformationResult>> future;
  };
  ParallelLevels(Session& session, MeshRefinement refinement, GeomId coarse, GeomId fine, ForceTransfer transfer);
  std::optional<LevelResult> take_ready();  // requires mutex_

  Session& session_;
  MeshRefinement refinement_;
  GeomId coarse_id_, fine_id_;
  ForceTransfer transfer_;
  mutable std::mutex mutex_;
  uint64_t next_submission_ = 1;
  uint64_t delivered_key_ = 0;  // 2 * submission + fine of the last delivered result
  std::vector<Pending> pending_;
};

}  // namespace softshell
