#pragma once
// Shared helpers of the service, HTTP and embedded tests: small meshes whose numbers are exact in
// f32 (so binary and JSON carry the same values), determined requests, limit evaluation.

#include <chrono>
#include <vector>

#include "softshell/deformation.h"
#include "softshell/limit_evaluator.h"
#include "softshell/material.h"
#include "test_meshes.h"

namespace softshell::test {

/// E, nu and t that f32 represents exactly.
inline Material exact_material() { return Material{1.0e6, 0.25, 0.015625, 1000.0}; }

/// A flat n x n grid over [0, 1]^2 (n a power of two: coordinates exact in f32).
inline ControlMesh exact_grid(int n = 4) { return make_grid(n, n); }

/// The four corner control points of exact_grid(n) fixed on all axes.
inline std::vector<VertexConstraint> pinned_corners(int n = 4) {
  std::vector<VertexConstraint> out;
  for (int j : {0, n}) {
    for (int i : {0, n}) out.push_back({grid_index(n, i, j), kAxisAll, Vec3::Zero()});
  }
  return out;
}

/// A determined request on exact_grid(n): corners pinned, a force at an interior point whose
/// size depends on `k` (so successive requests give different results).
inline DeformationRequest pinned_push(int k = 1, int n = 4) {
  DeformationRequest r;
  r.vertex_constraints = pinned_corners(n);
  r.forces.push_back({grid_index(n, n / 2, n / 2), Vec3(0.0, 0.0, -0.25 * k)});
  return r;
}

/// The limit position at `p` for control point positions `positions`.
inline Vec3 limit_point(const LimitEvaluator& evaluator, const std::vector<Vec3>& positions, const SurfacePoint& p) {
  return evaluator.evaluate(p, positions).position;
}

using Ms = std::chrono::milliseconds;
inline double seconds_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

}  // namespace softshell::test
