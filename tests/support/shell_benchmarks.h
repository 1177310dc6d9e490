#pragma once
// Classic thin-shell benchmark geometries as Catmull-Clark control meshes (shared by the engine
// tests and tests/bench). See shell-theory notes §2 and the README's accuracy tables.

#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/deformation.h"
#include "softshell/material.h"

namespace softshell::test {

/// Rectangular plate [0, a] x [0, b] in z = 0 with nx x ny faces (square: make_plate). With
/// `ghost_ring`, one more ring of faces lies outside the plate and the mesh uses
/// BoundaryMode::kNone, so the interior faces are the plate (a full B-spline space up to the
/// edges, for exact clamped conditions and free edges).
struct Plate {
  ControlMesh mesh;
  int n = 0;           // faces along x of the physical plate (per side for a square)
  int ny = 0;          // faces along y
  bool ghost = false;
  int points_per_side = 0;  // control points per row (along x)
  int index(int i, int j) const { return j * points_per_side + i; }  // control point (i, j)
  /// The surface point at the plate's centre (n even).
  SurfacePoint centre() const;
  /// The face and (u, v) of plate parameter (s, t) in [0, 1]^2 (u along x, v along y).
  SurfacePoint at(double s, double t) const;
};
Plate make_plate(int n, double a, bool ghost_ring = false);
Plate make_rectangle(int nx, int ny, double a, double b, bool ghost_ring = false);

/// Vertex constraints of a simply supported plate: w = 0 on the boundary row, in-plane DOFs fixed.
std::vector<VertexConstraint> simply_supported(const Plate& plate);
/// In-plane DOFs fixed everywhere (the flat plate's membrane part decouples).
std::vector<VertexConstraint> in_plane_fixed(const Plate& plate);

/// The Scordelis-Lo roof: R = 25, L = 50, +-40 degrees, with nt faces around and nl along.
/// Control points are fitted so that the limit surface passes through the cylinder at every
/// vertex of the control grid (the limit of a control point is not the point).
struct ScordelisLo {
  ControlMesh mesh;
  int nt = 0, nl = 0;
  int index(int i, int j) const { return j * (nt + 1) + i; }  // i around, j along
  /// The surface point at the middle of the free edge at theta = -40 degrees.
  SurfacePoint free_edge_midpoint() const;
  static constexpr double kRadius = 25.0, kLength = 50.0, kHalfAngleDeg = 40.0;
  static Material material() { return Material{4.32e8, 0.0, 0.25, 0.0}; }
  /// Rigid diaphragms at both curved ends (u_x = u_z = 0) and one axial DOF.
  std::vector<VertexConstraint> supports() const;
  static constexpr double kReference = 0.3006;  // Kirchhoff-Love converged value (GeoPDEs 0.3005925)
};
ScordelisLo make_scordelis_lo(int nt, int nl);

/// Flat meshes (z = 0) with extraordinary vertices, for patch tests and convergence studies.
///
/// `sectors` sectors of k x k quads around one vertex (sector i is the parallelogram spanned by the
/// unit vectors at angles 2 pi i / valence and 2 pi (i + 1) / valence): all `valence` sectors, an
/// interior extraordinary vertex of that valence; fewer, a boundary vertex with `sectors` faces.
ControlMesh fan_plate(int valence, int k, int sectors = -1);
/// An n-gon in the middle and `rings` rings of quads around it: its corners have valence 3, and
/// its centre becomes an extraordinary vertex of valence n after one subdivision step.
ControlMesh ngon_plate(int n, int rings);
/// Control points on the boundary (on an edge of one face).
std::vector<char> boundary_points(const ControlMesh& mesh);
/// Moves every interior control point by up to `amount` (uniformly random, in the plane z = 0).
void perturb_interior(ControlMesh& mesh, double amount, unsigned seed);

/// The square plate [0, a]^2 with n x n faces (n a multiple of 4, at least 8) in which the two
/// 2 x 2 blocks around the grid points (n/4, n/4) and (3n/4, 3n/4) are each split into two
/// quads, two more quads and two triangles, so that after one subdivision step each block holds
/// two valence-3 and two valence-5 extraordinary vertices. Point-symmetric about the centre,
/// which is a regular control point; its limit point is the plate's centre.
struct EvPlate {
  ControlMesh mesh;
  SurfacePoint centre;
};
EvPlate make_ev_plate(int n, double a);

/// Navier's series for the centre deflection of a simply supported square plate under a
/// uniform load, w D / (q a^4) (to 1e-12).
inline constexpr double kNavierCentreDeflection = 0.004062352661;

}  // namespace softshell::test
