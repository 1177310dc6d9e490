#pragma once
// Quadrature rules over the faces of a Catmull-Clark limit surface (private to the engine).
//
// Regular faces are bicubic patches: one Gauss rule over the face. Faces next to an extraordinary
// vertex (EV) or a sharp feature are piecewise polynomial on dyadic sub-squares that shrink toward
// that corner (Bfr's patch tree), so the domain is split dyadically toward every irregular corner
// and each cell gets its own Gauss rule.

#include <array>
#include <cstdint>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/engine/shell_model.h"
#include "softshell/limit_evaluator.h"

namespace softshell::engine::internal {

/// Gauss-Legendre points and weights on [0, 1].
void gauss_legendre_01(int n, std::vector<double>& points, std::vector<double>& weights);

/// Which corners of each (face, sub-face) domain need refinement: bit c set for corner c in the
/// protocol's order (0 = (0,0), 1 = (1,0), 2 = (1,1), 3 = (0,1)).
class IrregularCorners {
 public:
  explicit IrregularCorners(const ControlMesh& mesh);
  uint8_t corners(int32_t face, int32_t subface) const;

 private:
  const ControlMesh& mesh_;
  std::vector<char> irregular_vertex_;  // per control point
};

/// The (u, v) points and weights of one (sub-)face: Gauss rules on dyadic cells refined
/// `levels` times toward each corner in `corner_mask`. Weights sum to 1 (the domain's area).
void face_rule(int gauss_points, int levels, uint8_t corner_mask, std::vector<std::array<double, 2>>& out_uv,
               std::vector<double>& out_weight);

}  // namespace softshell::engine::internal
