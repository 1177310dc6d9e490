#pragma once
// The largest stress over a model's quadrature points, for the linear and the nonlinear stresses
// alike (private to the engine).

#include <array>
#include <cstdint>
#include <map>
#include <utility>
#include <vector>

#include "softshell/engine/shell_model.h"

namespace softshell::engine::internal {

/// The sample of largest von Mises stress at the quadrature points. `evaluate(face, subface, uvs,
/// out)` appends a Sample (with `von_mises()`) per (u, v); the points are grouped by (face,
/// sub-face) so that each face's basis is set up once.
template <class Sample, class Evaluate>
Sample max_von_mises_at_quadrature_points(const ShellModel& model, Evaluate&& evaluate) {
  std::map<std::pair<int32_t, int32_t>, std::vector<std::array<double, 2>>> groups;
  for (const QuadraturePoint& q : model.quadrature()) groups[{q.point.face, q.point.subface}].push_back({q.point.u, q.point.v});
  Sample max{};
  std::vector<Sample> samples;
  bool first = true;
  for (const auto& [key, uvs] : groups) {
    samples.clear();
    evaluate(key.first, key.second, uvs, samples);
    for (const Sample& s : samples) {
      if (first || s.von_mises() > max.von_mises()) {
        max = s;
        first = false;
      }
    }
  }
  return max;
}

}  // namespace softshell::engine::internal
