#pragma once
// Classic thin-shell benchmark geometries as Catmull-Clark control meshes (shared by the engine
// tests and tests/bench). See shell-theory notes §2 and the README's accuracy tables.

#include <functional>
#include <vector>

#include <Eigen/Core>

#include "softshell/control_mesh.h"
#include "softshell/deformation.h"
#include "softshell/limit_evaluator.h"
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

/// A tensor-product patch of nu x nv physical faces with one ring of ghost faces around it
/// (BoundaryMode::kNone): the physical faces are the bicubic B-spline patches over control
/// indices i in [0, nu], j in [0, nv]; the ghost rows are i = -1, nu + 1 and j = -1, nv + 1.
/// Its edges are free (the ghost points complete the B-spline space) unless made mirror planes.
struct GhostGrid {
  ControlMesh mesh;
  int nu = 0, nv = 0;
  /// Control point (i, j), i in [-1, nu + 1], j in [-1, nv + 1].
  int index(int i, int j) const { return (j + 1) * (nu + 3) + (i + 1); }
  /// The face and (u, v) of patch parameter (s, t) in [0, 1]^2.
  SurfacePoint at(double s, double t) const;
};
/// The grid over control points position(i, j) (ghost rows included).
GhostGrid make_ghost_grid(int nu, int nv, const std::function<Vec3(int, int)>& position);

/// Mirror symmetry planes on edges of a GhostGrid: the axis (0 = x, 1 = y, 2 = z) normal to the
/// plane through edge i = 0, i = nu, j = 0, j = nv, or -1 for a free edge. The control net must
/// be mirror-symmetric about each such plane (the row on the edge in the plane, the ghost row the
/// mirror image of the first inner row). The constraints restrict the displacement to the
/// mirror-symmetric part of the B-spline space of the whole (unfolded) shell: each ghost point
/// moves as the mirror image of its partner (Lagrange rows), and the points in the plane keep
/// their normal component at zero. A solve with them is the full model's, not an approximation
/// of the symmetry conditions by limit-point rows.
struct MirrorPlanes {
  int i_min = -1, i_max = -1, j_min = -1, j_max = -1;
};
void add_mirror_planes(const GhostGrid& grid, const MirrorPlanes& planes, DeformationRequest& request);

/// The pulled-out open cylinder of Sze, Liu and Lo 2004 (section 3.5): R = 4.953, L = 10.35,
/// t = 0.094, E = 10.5e6, nu = 0.3125, free ends, pulled by two opposite radial forces P at
/// mid-length, P_max = 40000. One octant: theta in [0, 90] degrees around (x = R cos theta,
/// z = R sin theta; i = 0..nt), y in [0, L/2] along (j = 0..nl; y = 0 the free end, y = L/2 the
/// mid-length plane); mirror planes z = 0, x = 0, y = L/2; the octant carries P/4 at A.
/// Control points are scaled so that the limit surface passes through the cylinder at every
/// vertex of the grid (a ring of radius R_c has its limit at R_c (4 + 2 cos dtheta) / 6).
struct PulloutCylinder {
  GhostGrid grid;
  static constexpr double kRadius = 4.953, kLength = 10.35, kMaxLoad = 40000.0;
  static Material material() { return Material{10.5e6, 0.3125, 0.094, 0.0}; }
  SurfacePoint a() const { return grid.at(1.0, 1.0); }  ///< the load point (theta = 90, y = L/2), w_A = u_z
  SurfacePoint b() const { return grid.at(0.0, 1.0); }  ///< theta = 0, y = L/2: -u_B = -u_x
  SurfacePoint c() const { return grid.at(0.0, 0.0); }  ///< theta = 0, y = 0 (free end): -u_C = -u_x
  /// Mirror constraints and the octant's load P/4 at A (radially out, +z).
  DeformationRequest request(double load) const;
};
PulloutCylinder make_pullout_cylinder(int nt, int nl);

/// Sze, Liu and Lo 2004, their Table for the pulled-out cylinder (24 x 36 mesh of the octant):
/// P / P_max, w_A, -u_B, -u_C. Quoted from zanoni-mbdyn/MBDyn
/// tests/plates/sze2004/sze35/sze35_ref.dat ("results from [Sze 2004] (24x36 mesh)", its
/// sze.tex), which names the points as above (its sze35.awk: A loaded, B at mid-length and C at
/// the free end, both at 90 degrees from A).
struct SzeRow {
  double load_fraction, first, second, third;
};
inline constexpr SzeRow kSzePulloutCylinder[] = {
    {0.025, 0.819, 0.864, 0.872}, {0.05, 1.260, 1.471, 1.493}, {0.075, 1.527, 1.901, 1.946},
    {0.10, 1.707, 2.217, 2.293},  {0.15, 1.936, 2.641, 2.792}, {0.20, 2.079, 2.904, 3.106},
    {0.25, 2.180, 3.087, 3.310},  {0.30, 2.257, 3.227, 3.452}, {0.35, 2.321, 3.342, 3.556},
    {0.40, 2.376, 3.443, 3.632},  {0.45, 2.425, 3.539, 3.688}, {0.50, 2.473, 3.653, 3.718},
    {0.525, 2.543, 4.061, 3.580}, {0.55, 2.577, 4.171, 3.518}, {0.60, 2.618, 4.274, 3.452},
    {0.65, 2.648, 4.338, 3.410},  {0.70, 2.672, 4.385, 3.378}, {0.75, 2.692, 4.423, 3.353},
    {0.80, 2.710, 4.455, 3.332},  {0.85, 2.726, 4.483, 3.313}, {0.90, 2.741, 4.508, 3.297},
    {0.95, 2.755, 4.530, 3.283},  {1.00, 2.768, 4.551, 3.269},
};

/// The hemispherical shell with an 18 degree hole of Sze, Liu and Lo 2004 (section 3.4):
/// R = 10, t = 0.04, E = 6.825e7, nu = 0.3, the polar hole and the equator free, two pairs of
/// opposite radial point forces P on the equator (out at phi = 0, in at phi = 90), P_max = 400.
/// One quarter: phi in [0, 90] degrees around (i = 0..nphi), colatitude from 90 (the equator,
/// j = 0) to 18 degrees (the hole, j = npsi); mirror planes y = 0 and x = 0; each load point lies
/// in a mirror plane, so the quarter carries P/2 at each. One control point's u_z is held (the
/// only rigid motion the planes leave; the loads have no z resultant, so it carries nothing).
/// Control points scaled so that the limit surface passes through the sphere at every vertex.
struct OpenHemisphere {
  GhostGrid grid;
  static constexpr double kRadius = 10.0, kHoleDeg = 18.0, kMaxLoad = 400.0;
  static Material material() { return Material{6.825e7, 0.3, 0.04, 0.0}; }
  SurfacePoint a() const { return grid.at(0.0, 0.0); }  ///< (R, 0, 0), pulled out: u_A = u_x
  SurfacePoint b() const { return grid.at(1.0, 0.0); }  ///< (0, R, 0), pushed in: -u_B = -u_y
  DeformationRequest request(double load) const;
};
OpenHemisphere make_open_hemisphere(int nphi, int npsi);

/// Sze, Liu and Lo 2004, their Table for the hemisphere (16 x 16 mesh of the quarter):
/// P / P_max, u_A (the outward load point), -u_B (the inward one); `third` unused. Quoted from
/// ElmerCSC/elmerfem fem/tests/Shell_OpenHemisphere_High_Order/runhemisphere.m ("Reference
/// results from the paper Sze KY, Liu XH, Lo SH ..."), which plots the second column against the
/// displacement of its outward-loaded point and the third against minus that of its inward-loaded
/// one, with P = 400 P / P_max the force of the whole shell (its quarter model carries half, as
/// in smdogroup/tacs tests/integration_tests/test_shell_hemisphere_nonlinear.py: PMax / 2).
inline constexpr SzeRow kSzeHemisphere[] = {
    {0.05, 0.855, 0.955, 0}, {0.10, 1.499, 1.840, 0}, {0.15, 1.969, 2.604, 0}, {0.20, 2.321, 3.261, 0},
    {0.25, 2.596, 3.833, 0}, {0.30, 2.819, 4.339, 0}, {0.35, 3.002, 4.790, 0}, {0.40, 3.158, 5.196, 0},
    {0.45, 3.291, 5.565, 0}, {0.50, 3.406, 5.902, 0}, {0.55, 3.508, 6.212, 0}, {0.60, 3.598, 6.497, 0},
    {0.65, 3.678, 6.761, 0}, {0.70, 3.750, 7.006, 0}, {0.75, 3.816, 7.234, 0}, {0.80, 3.875, 7.448, 0},
    {0.85, 3.929, 7.647, 0}, {0.90, 3.979, 7.835, 0}, {0.95, 4.025, 8.011, 0}, {1.00, 4.067, 8.178, 0},
};

/// Navier's series for the centre deflection of a simply supported square plate under a
/// uniform load, w D / (q a^4) (to 1e-12).
inline constexpr double kNavierCentreDeflection = 0.004062352661;

/// The large-deflection cantilever under a dead tip load (elastica; Mattiasson 1981, as issue 16
/// quotes it): for P L^2 / EI = load, the tip's vertical and horizontal displacement over L.
struct ElasticaPoint {
  double load, vertical, horizontal;
};
inline constexpr ElasticaPoint kMattiassonCantilever[] = {
    {1.0, 0.30172, 0.05643}, {2.0, 0.49346, 0.16064}, {5.0, 0.71379, 0.38763}, {10.0, 0.81061, 0.55500}};

/// A rigid turn `rotation` about the point `through`: the displacement that carries `x` with it.
inline Vec3 rigid_turn(const Eigen::Matrix3d& rotation, const Vec3& through, const Vec3& x) {
  return rotation * (x - through) + through - x;
}

/// Lagrange rows that turn the first surface tangent (d/du) at each point by `rotation`: an end
/// moment's rotation prescribed on a strip's tip (the tangent's change, exact in the control points).
std::vector<LagrangeConstraint> turned_tangents(const LimitEvaluator& evaluator, const std::vector<SurfacePoint>& points,
                                                const Eigen::Matrix3d& rotation);

/// The lowest 5% of the control points (by y) of every connected component, at least four, all
/// axes fixed: the supports of bench_engine and of the tests on every shipped mesh. Per part,
/// because a whole part can lie above another part's 5%; four, because a free part needs three
/// held points and the tiny all-valence-3 parts (a cube's 8 control points) have zero-energy
/// modes beyond the rigid ones that three points do not stop.
std::vector<VertexConstraint> bottom_supports(const ControlMesh& mesh, const std::vector<int32_t>& component_of);
/// The centre of the face whose centre lies highest (largest y), where a grab pulls.
SurfacePoint topmost_face_centre(const LimitEvaluator& limit);

}  // namespace softshell::test
