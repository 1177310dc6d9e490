#pragma once
// Private: exact evaluation of the Catmull-Clark limit surface on the faces that are not one
// bicubic B-spline patch (faces at extraordinary vertices, n-gons, quads next to non-quads).
//
// A face's limit surface depends only on its 1-ring (the faces around its corners). The 1-ring is
// numbered canonically (`extract_neighbourhood`), and faces whose numbered 1-rings have the same
// topology share one `FaceProgram`:
//  - the program refines the 1-ring with OpenSubdiv (Far::TopologyRefiner + StencilTableFactory)
//    until every piece of the face is either a regular bicubic patch (16 control points, with
//    OpenSubdiv's boundary phantoms) or a quad with one extraordinary corner and an all-quad
//    1-ring: an `EvConfig`;
//  - an `EvConfig` is the numbered 1-ring of such a quad. OpenSubdiv's refinement of it gives the
//    subdivision matrix A, which maps the 1-ring onto the 1-ring of the child at the
//    extraordinary corner (same topology, same numbering), and the 16 control points of the
//    three other children, which are regular. A point at parameter distance ~2^-n from the
//    corner lies in a regular patch of A^(n-1) times the 1-ring: Stam's exact evaluation, with
//    the powers of A formed by repeated multiplication instead of an eigen-decomposition (which
//    does not exist for every valence). The derivatives use A^(n-1) without its eigenvalue-1 part
//    (the limit-position mask), so their weights keep full relative precision arbitrarily close
//    to the corner.
// Every subdivision rule comes from OpenSubdiv itself, so the surface cannot drift from its.

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

#include <Eigen/Core>
#include <opensubdiv/far/topologyLevel.h>
#include <opensubdiv/far/topologyRefiner.h>

namespace softshell::internal {

namespace Far = OpenSubdiv::Far;

using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

/// The 1-ring of a face of a topology level, numbered canonically from one of its corners: the
/// face's corners first (from `origin` on, in the face's order), then the vertices of the faces
/// around each corner in turn (counter-clockwise, starting at the face itself or, at a boundary,
/// at the first face after the boundary), each face's vertices read from that corner on.
struct Neighbourhood {
  std::vector<Far::Index> vertices;  // level vertex of each local vertex
  /// The topology in local numbers: the number of faces, then per face its size and vertices.
  /// Face 0 is the face itself, starting at local vertex 0.
  std::vector<int32_t> signature;
};

/// False if the 1-ring is not a manifold fan around every corner.
bool extract_neighbourhood(const Far::TopologyLevel& level, Far::Index face, int origin, Neighbourhood& out);

/// True if `v` is a regular vertex for a bicubic patch: all its faces quads, and 4 of them inside,
/// 2 (smooth boundary) or 1 (corner) on the boundary.
bool is_regular_vertex(const Far::TopologyLevel& level, Far::Index v);

/// The 4 x 4 control points of a regular quad, row i + 4 j for the point i along the edge from
/// corner `origin` to the next corner and j along the edge from `origin` to the previous one; the
/// face is the middle cell. Points across a boundary are OpenSubdiv's phantoms (2 P_boundary -
/// P_inner). Returns false if the face is not a regular patch.
struct PatchGrid {
  std::array<Far::Index, 16> index{};  // -1 for a phantom point
};
bool regular_grid(const Far::TopologyLevel& level, Far::Index face, int origin, PatchGrid& out);

/// The grid's points as rows of `vertex_weights` (level vertex -> weights over some base points).
RowMatrix grid_rows(const PatchGrid& grid, const RowMatrix& vertex_weights);

/// Uniform cubic B-spline tensor basis at (s, t) in the middle cell: 6 x 16, rows N, N_s, N_t,
/// N_ss, N_st, N_tt, columns as PatchGrid.
void bspline_basis(double s, double t, double out[6][16]);

/// The position of `v` in a vertex list, or -1.
int position_in(Far::ConstIndexArray verts, Far::Index v);

/// A Far refiner of the topology in a signature (EDGE_AND_CORNER boundaries: the artificial
/// boundary of a 1-ring does not reach the points its face needs), refined uniformly `levels`
/// times, with every refined vertex as weights over the base vertices.
struct LocalRefinement {
  std::unique_ptr<Far::TopologyRefiner> refiner;
  std::vector<RowMatrix> weights;  // per level: vertices x base vertices
  int base_size = 0;
};
LocalRefinement refine_local(const std::vector<int32_t>& signature, int levels);

/// The child face of `face` (next level) that contains child vertex `child`, or -1.
Far::Index child_face_with(const Far::TopologyLevel& parent, const Far::TopologyLevel& child_level, Far::Index face,
                           Far::Index child);

/// Gauss-Legendre points and weights on [0, 1].
void gauss_legendre_01(int n, std::vector<double>& points, std::vector<double>& weights);

/// The neighbourhood of a quad with one extraordinary corner (see the file comment).
class EvConfig {
 public:
  /// nullptr if the topology is not such a neighbourhood (the child's 1-ring has another
  /// topology, the other children are not regular patches) or has no separated pair of
  /// dominant eigenvalues (valence 2).
  static std::unique_ptr<EvConfig> build(const std::vector<int32_t>& signature);

  int size() const { return size_; }
  /// Weights over the K neighbourhood points at (s, t) in [0, 1]^2 (the extraordinary corner at
  /// (0, 0)): `out` is 6 x K row-major, rows N, N_s, N_t, N_ss, N_st, N_tt. At the corner itself
  /// (and closer than 2^-1000) the position is the limit position; N_s and N_t are two vectors
  /// spanning the tangent plane there (see LimitEvaluator's documentation), second rows zero.
  void evaluate(double s, double t, double* out) const;

  /// Where (s, t) lies: ring n >= 1 (0 at the corner itself), sub-patch 1..3 and the
  /// sub-patch's own (a, b).
  struct Location {
    int ring = 0, patch = 0;
    double a = 0.0, b = 0.0;
  };
  static Location locate(double s, double t);
  /// The 16 control points of that ring's sub-patch without the limit mask: P_patch B^(ring-1)
  /// (16 x K); `deep` is storage for rings beyond the table.
  const RowMatrix& ring_points(int ring, int patch, RowMatrix& deep) const;
  /// The B-spline rows (6 x 16, row-major) of a location, scaled to (s, t) derivatives.
  static void basis_rows(const Location& at, double* out);

  const Eigen::RowVectorXd& limit_mask() const { return limit_; }

  /// A quadrature rule for the square [0, h]^2 at the corner, which holds infinitely many
  /// polynomial rings: the g x g Gauss rule with its weights multiplied by the returned factors
  /// (order i + g j, point i along s, j along t). The factors make the rule exact for the
  /// Jacobian of the characteristic map (the map by the two dominant eigenvectors of A), the
  /// leading term near the corner of the area element, of the surface gradient of every basis
  /// function, and so of every integrand of the shell. By self-similarity the same factors serve
  /// every h = 2^-k. Computed once per g; thread-safe.
  const std::vector<double>& corner_rule(int g) const;

  /// The exact integral over [0, 2^-level]^2 of N_i (x_s x x_t) ds dt for every neighbourhood
  /// point i, for neighbourhood points x (K x 3): K x 3. (A trilinear form, summed over the
  /// infinitely many rings in closed form.) Thread-safe.
  void normal_integral(int level, const RowMatrix& x, RowMatrix& out) const;

 private:
  std::vector<double> compute_corner_rule(int g) const;
  /// U[a][b][c] = integral over [0, 1]^2 of phi_a phi_b,s phi_c,t (computed once).
  const std::vector<double>& normal_tensor() const;
  static constexpr int kTableLevels = 16;
  int size_ = 0;
  RowMatrix subdivision_;                         // A, K x K
  Eigen::RowVectorXd limit_;                      // l: l A = l, l 1 = 1
  RowMatrix tangents_;                            // 2 x K at the corner
  std::vector<std::array<RowMatrix, 3>> table_;   // [n-1][k-1] = P_k B^(n-1), 16 x K, B = A - 1 l
  std::vector<RowMatrix> powers_;                 // B^(2^j)
  Eigen::MatrixXd chart_;                         // K x 2: the dominant invariant pair of B
  double chart_ratio_ = 0.0;                      // det of A on it: the rings' area ratio
  mutable std::mutex rules_mutex_;
  mutable std::map<int, std::vector<double>> rules_;  // corner rules by g
  mutable std::once_flag normal_once_;
  mutable std::vector<double> normal_tensor_;
};

/// The exact evaluation of every face with one numbered 1-ring topology.
class EvConfigStore;
class FaceProgram {
 public:
  /// nullptr if the face cannot be split into regular and EvConfig pieces within a few levels
  /// (a vertex of valence 2, where Catmull-Clark has no separated tangent plane modes).
  static std::unique_ptr<FaceProgram> build(const std::vector<int32_t>& signature, EvConfigStore& configs);

  /// Local points (the Neighbourhood's vertices).
  int size() const { return size_; }
  /// Weights over the local points at (u, v) of sub-face `subface` (the protocol's sub-face
  /// coordinates): `out` is 6 x size() row-major, rows N, N_u, N_v, N_uu, N_uv, N_vv.
  /// `scratch` is reused storage.
  void evaluate(int subface, double u, double v, double* out, std::vector<double>& scratch) const;
  /// The same at many points of one sub-face, grouped by polynomial piece so that each group is
  /// two small matrix products: `out` is (6 count) x size(), rows 6i .. 6i+5 for point i.
  void evaluate_many(int subface, const std::array<double, 2>* uvs, size_t count, RowMatrix& out) const;

  /// EvConfig::corner_rule for the square cell of side `size` at corner `corner` of sub-face
  /// `subface`, in the cell's point order (i + g j, point i along u, j along v). False if the
  /// corner is regular or the cell is larger than its extraordinary piece.
  bool corner_rule(int subface, int corner, double size, int g, std::vector<double>& out) const;
  /// EvConfig::normal_integral for that cell, for local points x (size() x 3): size() x 3.
  bool corner_normal_integral(int subface, int corner, double size, const RowMatrix& x, RowMatrix& out) const;

 private:
  struct Piece {
    int subface = 0;
    double umin = 0, umax = 1, vmin = 0, vmax = 1;  // domain in sub-face coordinates
    double ou = 0, ov = 0;                          // sub-face coordinates of the piece's (0, 0)
    double su = 1, sv = 0, tu = 0, tv = 1;          // s = su (u - ou) + sv (v - ov), t = tu (u - ou) + tv (v - ov)
    const EvConfig* config = nullptr;               // an extraordinary piece, or a regular patch
    RowMatrix matrix;                               // 16 x size() (regular) or K x size() (EvConfig)
  };
  const Piece& piece_at(int subface, double u, double v) const;
  /// Rows 6i .. 6i+5 of `out` from (s, t) derivatives to (u, v) derivatives (the map is affine).
  static void to_subface(const Piece& piece, Eigen::Ref<RowMatrix> rows);
  /// The extraordinary piece at that corner, if a dyadic square of that size there lies in it.
  const Piece* corner_piece(int subface, int corner, double size) const;

  int size_ = 0;
  std::vector<Piece> pieces_;
  friend struct ProgramBuilder;
};

/// EvConfigs by signature, shared by the FacePrograms of one evaluator (null: not a config).
class EvConfigStore {
 public:
  const EvConfig* get(const std::vector<int32_t>& signature);

 private:
  std::map<std::vector<int32_t>, std::unique_ptr<EvConfig>> configs_;
};

/// FacePrograms by signature (null for a face that is not evaluable exactly).
class FaceProgramStore {
 public:
  const FaceProgram* get(const std::vector<int32_t>& signature);
  size_t size() const { return programs_.size(); }

 private:
  EvConfigStore configs_;
  std::map<std::vector<int32_t>, std::unique_ptr<FaceProgram>> programs_;
};

}  // namespace softshell::internal
