#pragma once
// Private: the objects behind LimitEvaluator, shared with Tessellation.
//
// Regular faces (one bicubic B-spline patch) are evaluated by OpenSubdiv Bfr, which is exact
// there; every other face by an exact FaceProgram (exact_limit.h), shared by all faces with the
// same 1-ring topology. Faces next to sharp features (only with Options::sharp_features) keep
// Bfr's approximation. Everything is built once, when the evaluator is created, and immutable
// afterwards: the const evaluation functions are safe to call from many threads.

#include <memory>
#include <vector>

#include <opensubdiv/bfr/surface.h>
#include <opensubdiv/far/topologyRefiner.h>

#include "softshell/limit_evaluator.h"

namespace softshell::internal {
class FaceProgram;
class FaceProgramStore;
}  // namespace softshell::internal

namespace softshell::internal {

namespace Bfr = OpenSubdiv::Bfr;
namespace Far = OpenSubdiv::Far;

/// Builds a Far::TopologyRefiner for the mesh (scheme, boundary mode, creases and corners).
/// Throws Exception(kUnprocessable) if OpenSubdiv rejects the topology.
std::unique_ptr<Far::TopologyRefiner> make_refiner(const ControlMesh& mesh);

struct FaceSurface {
  Bfr::Surface<double> surface;       // Bfr faces only (invalid for ghost and exact faces)
  const FaceProgram* program = nullptr;  // exact faces: support = the program's local points
  bool has_surface = false;           // false for ghost faces
  std::vector<int32_t> support;       // control point indices, as Bfr or the program orders them
  bool has_duplicates = false;     // a control point appears twice in `support` (tiny closed meshes)
  double subface_scale = 1.0;      // d(Bfr coordinate) / d(normalized sub-face coordinate)
};

}  // namespace softshell::internal

namespace softshell {

struct LimitEvaluator::Impl {
  ControlMesh mesh;
  Options options;
  std::unique_ptr<internal::Far::TopologyRefiner> refiner;  // base level only
  std::vector<internal::FaceSurface> faces;
  std::shared_ptr<internal::FaceProgramStore> programs;
  int32_t max_support = 0;

  /// Weights at a point (6 x support, row-major: N, N_u, N_v, N_uu, N_uv, N_vv, w.r.t. the
  /// sub-face's own coordinates), in support order (repeated points not merged).
  void weights(const SurfacePoint& p, double* out, std::vector<double>& scratch) const;

  /// Bfr (u, v) of a surface point (sub-face coordinates converted for n-gons).
  void bfr_coord(const SurfacePoint& p, double out_uv[2]) const;

  /// Evaluates positions and first derivatives (w.r.t. the sub-face's own u, v) at many points of
  /// one (sub-)face for the control positions given (#V). No allocation beyond `scratch`.
  void evaluate_many(int32_t face, int32_t subface, const std::array<double, 2>* uvs, size_t count,
                     const std::vector<Vec3>& positions, Vec3* out_position, Vec3* out_du, Vec3* out_dv,
                     std::vector<double>& scratch) const;
};

}  // namespace softshell
