#pragma once
// Quadrature rules over the faces of a Catmull-Clark limit surface (private to the engine).
//
// Regular faces are bicubic patches: one Gauss rule over the face. Faces next to an extraordinary
// vertex (EV) or a sharp feature are piecewise polynomial on dyadic sub-squares that shrink toward
// that corner (the rings of the exact evaluation), so the domain is split dyadically toward every
// irregular corner and each cell gets its own Gauss rule. Quads whose corners are regular but
// touch a non-quad face are 2 x 2 bicubic pieces (the children of one subdivision step): they are
// split once. Cells whose parametrization is strongly non-uniform are
// split further where the geometry is known (face_rule).

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "softshell/control_mesh.h"
#include "softshell/gauss_legendre.h"
#include "softshell/engine/shell_model.h"
#include "softshell/limit_evaluator.h"

namespace softshell::engine::internal {

/// Which corners of each (face, sub-face) domain need refinement: bit c set for corner c in the
/// protocol's order (0 = (0,0), 1 = (1,0), 2 = (1,1), 3 = (0,1)); kSplitOnce set for a quad that
/// is 2 x 2 polynomial pieces (a corner touches a non-quad face).
inline constexpr uint8_t kSplitOnce = 1u << 4;

class IrregularCorners {
 public:
  explicit IrregularCorners(const ControlMesh& mesh);
  uint8_t corners(int32_t face, int32_t subface) const;

 private:
  const ControlMesh& mesh_;
  std::vector<char> irregular_vertex_;  // per control point
  std::vector<char> next_to_non_quad_;  // per control point: one of its faces is not a quad
};

/// A square [u0, u0 + size] x [v0, v0 + size] of a (sub-)face's parameter domain.
struct Cell {
  double u0 = 0.0, v0 = 0.0, size = 1.0;
  /// A cell at an extraordinary corner (which holds infinitely many polynomial rings): the
  /// corner (0..3) and the factors of its Gauss weights (LimitEvaluator::ev_corner_weights).
  int ev_corner = -1;
  std::vector<double> weight_factors;
  /// Points per direction of its Gauss rule (0 = the face's, QuadratureOptions::gauss_points).
  int gauss_points = 0;
};

/// Ring cells this small or smaller (depth 3 and deeper toward an irregular corner) get
/// QuadratureOptions::ev_ring_gauss_points.
inline constexpr double kSmallRingCellSize = 0.125;

/// Its four quarters (the one at an extraordinary corner keeps the corner's weight factors).
std::array<Cell, 4> split(const Cell& cell);

/// The cells of one (sub-)face: the unit square split dyadically `levels` times toward each
/// corner in `corner_mask`, and at least once if it has kSplitOnce. Their areas sum to 1. The
/// cells at an extraordinary corner get the evaluator's weight factors for `gauss_points`; ring
/// cells of kSmallRingCellSize or smaller get `ring_gauss_points` (0 = `gauss_points`). Cells
/// with the face's rule come first.
void face_cells(const LimitEvaluator& evaluator, int32_t face, int32_t subface, int gauss_points,
                int ring_gauss_points, int levels, uint8_t corner_mask, std::vector<Cell>& out);

/// The tensor Gauss rule on each cell (Cell::gauss_points, or `gauss_points` where that is 0),
/// cell after cell; the weights include the cell's area (and its weight factors). The points of
/// cell c are [first_point[c], first_point[c + 1]).
void cell_points(const std::vector<Cell>& cells, int gauss_points, std::vector<std::array<double, 2>>& out_uv,
                 std::vector<double>& out_weight, std::vector<size_t>& first_point);

/// The model's rule on one (sub-)face for `quad`: face_cells, then (up to
/// quad.max_distortion_splits rounds) the cells whose parametrization is far from uniform split in
/// four; their points and weights (cell_points) and the stencils there (6 rows per point,
/// LimitEvaluator::face_stencils), which the distortion test needed anyway. The linear model is
/// integrated on it; the nonlinear shell builds a cheaper rule with fewer levels the same way.
struct FaceRule {
  std::vector<Cell> cells;
  std::vector<std::array<double, 2>> uvs;
  std::vector<double> weights;
  std::vector<size_t> first_point;
  std::vector<int32_t> indices;  // the face's control points
  Eigen::MatrixXd basis;         // 6 rows per point, a column per control point
};
void face_rule(const LimitEvaluator& evaluator, const QuadratureOptions& quad, int32_t face, int32_t subface,
               uint8_t corner_mask, FaceRule& out);

/// The pressure load (integral of N_A n dA, 3 x indices.size(), columns for the control points
/// `indices`) of the cells at extraordinary corners, exactly (LimitEvaluator::
/// ev_corner_normal_weights: no point rule integrates it there); `exact[c]` set for those cells.
Eigen::Matrix3Xd exact_corner_normal_weights(const LimitEvaluator& evaluator, int32_t face, int32_t subface,
                                             const std::vector<Cell>& cells, const std::vector<int32_t>& indices,
                                             std::vector<char>& exact);

}  // namespace softshell::engine::internal
