#pragma once
// Issue 16's drag, set up once for the benchmarks that measure it (bench_engine's nonlinear table,
// bench_nonlinear_passes): the mesh scaled to a 1 m bounding diagonal, the lowest 5% of the control
// points held, a grab (limit constraint) at the centre of the topmost face, dragged across the
// object's thinnest horizontal extent (out of the plane of a flat object) to 30% of its size.

#include <cstdio>
#include <cstdlib>
#include <memory>

#include "shell_benchmarks.h"
#include "softshell/deformation.h"
#include "softshell/engine/nonlinear_solver.h"
#include "softshell/engine/shell_model.h"
#include "softshell/material.h"

namespace softshell::bench {

/// The benchmarks' aluminium-like material: E = 6.9e10 Pa, nu = 0.32, t = 2 mm.
inline const Material kMaterial{6.9e10, 0.32, 0.002, 2700.0};

struct Drag {
  std::shared_ptr<const engine::ShellModel> model;
  DeformationRequest request;  ///< the supports and the grab, not yet moved
  Vec3 direction = Vec3::UnitX();

  /// The grab's displacement after step `k` of `steps`.
  Vec3 grab_at(int k, int steps) const { return (0.3 * k / steps) * direction; }
};

/// The nonlinear solver's options for the drag benchmarks, with their A/B switches:
/// SOFTSHELL_BENCH_EXACT_DIRECTIONS (set: exact Newton directions throughout),
/// SOFTSHELL_BENCH_EARLY_RULE_LEVELS (NonlinearOptions::early_rule_levels; -1 turns it off),
/// SOFTSHELL_BENCH_TANGENT_GAUSS_POINTS (NonlinearOptions::tangent_gauss_points) and
/// SOFTSHELL_BENCH_TIMED_REFRESH (set: NonlinearOptions::reproducible off, the refresh rule timed,
/// so that a build's paths follow the host's timings; by default it repeats its paths exactly and
/// two solvers differ only by what they change).
inline engine::NonlinearOptions drag_options() {
  engine::NonlinearOptions options;
  options.approximate_directions = std::getenv("SOFTSHELL_BENCH_EXACT_DIRECTIONS") == nullptr;
  options.reproducible = std::getenv("SOFTSHELL_BENCH_TIMED_REFRESH") == nullptr;
  if (const char* levels = std::getenv("SOFTSHELL_BENCH_EARLY_RULE_LEVELS")) options.early_rule_levels = std::atoi(levels);
  if (const char* points = std::getenv("SOFTSHELL_BENCH_TANGENT_GAUSS_POINTS")) options.tangent_gauss_points = std::atoi(points);
  return options;
}

/// kMaterial, or its thickness from SOFTSHELL_BENCH_THICKNESS_MM (0.1..100 mm on the 1 m object):
/// how the drag's cost depends on how slender the shell is.
inline Material drag_material() {
  Material material = kMaterial;
  if (const char* mm = std::getenv("SOFTSHELL_BENCH_THICKNESS_MM")) {
    const double t = std::atof(mm);
    if (!(t >= 0.1 && t <= 100.0)) {
      std::fprintf(stderr, "SOFTSHELL_BENCH_THICKNESS_MM must be 0.1..100 (got '%s')\n", mm);
      std::exit(2);
    }
    material.thickness = 1e-3 * t;
  }
  return material;
}

inline Result<Drag> setup_drag(ControlMesh mesh) {
  const double scale = 1.0 / mesh.bounding_diagonal();
  for (Vec3& p : mesh.positions()) p *= scale;
  auto model = engine::ShellModel::build(mesh, drag_material());
  if (!model.ok()) return model.error();
  Drag drag;
  drag.model = *model;
  Vec3 low = mesh.positions()[0], high = low;
  for (const Vec3& p : mesh.positions()) {
    low = low.cwiseMin(p);
    high = high.cwiseMax(p);
  }
  drag.direction = (high - low).x() < (high - low).z() ? Vec3(1, 0, 0) : Vec3(0, 0, 1);
  drag.request.vertex_constraints = test::bottom_supports(mesh, drag.model->component_of());
  drag.request.limit_constraints.push_back({test::topmost_face_centre(drag.model->evaluator()), Vec3::Zero(), {}, {}});
  return drag;
}

}  // namespace softshell::bench
