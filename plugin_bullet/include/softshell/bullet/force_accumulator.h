#pragma once
/// \file
/// \brief `ForceAccumulator`: sums forces at limit-surface points into control-point forces with
/// the limit weights (f_A = N_A(p) F), the virtual-work consistent load of a point force.

#include <cstdint>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/deformation.h"
#include "softshell/limit_evaluator.h"

namespace softshell::bullet {

/// Accumulates point forces on the limit surface as forces on control points.
///
/// A force F at the limit point p(face, u, v) = sum_A N_A(p) x_A does the virtual work
/// F . delta p = sum_A (N_A(p) F) . delta x_A, so control point A gets N_A(p) F. The weights sum to
/// one, so the total force is kept exactly. Weights come from the exact limit stencil at the point
/// (OpenSubdiv Bfr, the same evaluation the simulation uses).
///
/// Memory: a dense array of #control points forces plus a list of the touched ones; `clear` and
/// `add` do not allocate once warmed up. Thread-safety: none (one per thread).
class ForceAccumulator {
 public:
  /// Copies of evaluators are cheap (shared immutable data).
  explicit ForceAccumulator(LimitEvaluator evaluator);

  /// Forgets every force (cost proportional to the number of touched control points).
  void clear();

  /// Adds `force` (N, in the control points' frame) acting at the limit point `point`.
  /// Throws `Exception(kInvalidArgument)` for a point the evaluator rejects.
  void add(const SurfacePoint& point, const Vec3& force);

  /// Adds a force directly on control point `index` (no spreading).
  void add(int32_t index, const Vec3& force);

  /// Moves every force a fraction `alpha` (0..1) toward `target`'s: f += alpha (target - f) on
  /// the control points either touches (exponential smoothing; alpha = 1 copies `target`).
  /// Forces that end up smaller than `drop_below` (N) are removed. Both must belong to meshes
  /// with the same number of control points.
  void blend_toward(const ForceAccumulator& target, double alpha, double drop_below = 0.0);

  /// Becomes a copy of `other`'s forces (same number of control points), reusing storage.
  void assign(const ForceAccumulator& other);

  /// Dense forces per control point (#control points, N).
  const std::vector<Vec3>& forces() const { return forces_; }
  /// Control points with a force since the last `clear`, in first-touched order.
  const std::vector<int32_t>& touched() const { return touched_; }
  /// Sum of all forces (N).
  Vec3 total() const { return total_; }
  /// True if no force was added since the last `clear`.
  bool empty() const { return touched_.empty(); }

  /// Appends one `PointForce` per touched control point, in ascending index order.
  void append_to(std::vector<PointForce>& out) const;

  /// Relative L2 difference |this - other| / max(|this|, |other|) of the two force fields
  /// (0 for two empty fields, 1 if exactly one is empty). Both must have the same evaluator size.
  double relative_difference(const ForceAccumulator& other) const;

  int32_t num_control_points() const { return static_cast<int32_t>(forces_.size()); }

 private:
  LimitEvaluator evaluator_;
  LimitStencil stencil_;  // scratch
  std::vector<Vec3> forces_;
  std::vector<uint8_t> is_touched_;
  std::vector<int32_t> touched_;
  Vec3 total_ = Vec3::Zero();
};

}  // namespace softshell::bullet
