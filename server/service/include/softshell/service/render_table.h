#pragma once
/// \file
/// \brief `RenderTable`: what a thin client (a browser, a Unity or Python client) needs once per
/// geometry and level to draw exactly the SDK's limit surface and to pick on it, without a
/// subdivision library of its own (`GET /geometries/{id}/render?level=L`, an extension).
///
/// It is the SDK's level-L `Tessellation` of the geometry's limit surface written out: for every
/// refined vertex the sparse limit stencils (position, d/du, d/dv) over the control points, so a
/// client computes `x = S P`, `x_u = S_u P`, `x_v = S_v P` and the normal `x_u x x_v` for any
/// control positions P (the rest shape or any result); the triangles; and for every refined quad
/// its root face, sub-face and quadtree path (paper Section 5.1), so a point on a triangle maps
/// back to `(face, subface, u, v)` as `Tessellation::surface_point` does. Layouts: docs/api-notes.md.

#include <cstdint>
#include <string>
#include <vector>

#include "softshell/limit_evaluator.h"
#include "softshell/result.h"
#include "softshell/session.h"

namespace softshell::service {

class Service;

/// The render table of one geometry at one tessellation level.
struct RenderTable {
  static constexpr int kMinLevel = 1;
  static constexpr int kMaxLevel = 6;
  /// Largest table served (refined quads); level 6 of a 3,000-face mesh is 12M quads.
  static constexpr int64_t kMaxQuads = 2'000'000;

  int32_t level = 0;
  int32_t control_points = 0;  ///< #V of the control mesh (columns of the stencils)
  int32_t vertices = 0;        ///< refined vertices (rows of the stencils)

  /// Stencils in compressed rows: vertex i uses entries offsets[i] .. offsets[i+1]-1 of
  /// `indices` (control points) and of the three weight arrays, which share one support.
  std::vector<uint32_t> offsets;  ///< vertices + 1
  std::vector<uint32_t> indices;
  std::vector<double> position, du, dv;

  /// Per refined quad, in `Tessellation::quads()` order: its four vertices (counter-clockwise),
  /// root face, sub-face, quadtree path (2 bits a level, first level lowest: 0 = (0,0),
  /// 1 = (1,0), 2 = (1,1), 3 = (0,1)), path depth, and rotation (vertex i sits at corner
  /// (i + rotation) % 4 of the path's rectangle).
  struct Quad {
    uint32_t vertices[4] = {0, 0, 0, 0};
    uint32_t root_face = 0;
    uint32_t subface = 0;
    uint32_t path = 0;
    uint8_t depth = 0;
    uint8_t rotation = 0;
  };
  std::vector<Quad> quads;
  /// Triangle 2q is quad q's vertices (0, 1, 2), triangle 2q + 1 its vertices (0, 2, 3)
  /// (`Tessellation::triangles()`); sent explicitly so a client can use it as its index buffer.
  std::vector<uint32_t> triangles;  ///< 3 per triangle

  size_t bytes() const;
};

/// The render table of geometry `id` at `level` (1..6), computed from the geometry's limit
/// evaluator (the one the simulation and `limit_comb` use) and `Tessellation::create`.
/// Available while the geometry precomputes. kNotFound for an unknown geometry,
/// kInvalidArgument for a level out of range, kResourceExhausted for a table over kMaxQuads.
Result<RenderTable> render_table(const Service& service, const GeomId& id, int level);

/// The same from an evaluator (what `render_table` calls; for SDK-side tests and tools).
Result<RenderTable> render_table(const LimitEvaluator& evaluator, int level);

/// Binary layout (little-endian; docs/api-notes.md): a 32-byte header (magic "SSRT", version 1,
/// level, control points, vertices, quads, stencil entries, flags = 0), offsets (u32), indices
/// (u32), position, du, dv weights (f32 each), quads (8 x u32), triangles (3 x u32).
std::string encode_render_table_binary(const RenderTable& table);
/// JSON layout: flat arrays, weights as doubles (exact).
std::string encode_render_table_json(const RenderTable& table);

}  // namespace softshell::service
