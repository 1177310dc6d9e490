#pragma once
/// \file
/// \brief `ControlMesh`: the coarse Catmull-Clark control mesh that is rendered, simulated and sent.

#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>  // cross products of Vec3

#include "softshell/result.h"

namespace softshell {

/// A point or vector in 3D, double precision. Lengths are in the mesh's length unit (metres when
/// the material is given in SI units).
using Vec3 = Eigen::Vector3d;

/// How OpenSubdiv treats the mesh boundary (PROTOCOL.md, "boundary").
enum class BoundaryMode : uint8_t {
  kEdgeAndCorner,  ///< boundary curves are cubic B-splines of the boundary points; corners interpolated
  kNone,           ///< faces touching the boundary are a ghost layer without limit surface
};

/// A sharp (or semi-sharp) edge between two control points: OpenSubdiv's `t crease` tag.
struct Crease {
  int32_t v0 = 0;          ///< control point index
  int32_t v1 = 0;          ///< control point index; (v0, v1) must be an edge of the mesh
  float sharpness = 0.0f;  ///< >= 0; 0 = smooth, >= 10 = infinitely sharp
};

/// A sharp corner at a control point: OpenSubdiv's `t corner` tag.
struct Corner {
  int32_t vertex = 0;      ///< control point index
  float sharpness = 0.0f;  ///< >= 0
};

/// A polygon mesh with faces of any size >= 3 whose Catmull-Clark limit surface is the object.
///
/// Storage only: construction checks that the arrays are consistent with each other, while
/// `validate_mesh()` (mesh_validation.h) checks what the simulation needs (indices in range,
/// manifold, oriented, non-degenerate). Faces list their control points counter-clockwise seen
/// from the side the normal points to. Immutable topology, mutable positions.
///
/// Thread-safety: const member functions may be called concurrently.
class ControlMesh {
 public:
  ControlMesh() = default;

  /// Faces as lists of control point indices.
  ControlMesh(std::vector<Vec3> positions, const std::vector<std::vector<int32_t>>& faces);

  /// Faces in flat form: `face_sizes[f]` indices of face f follow each other in `face_indices`.
  /// Throws `Exception(kInvalidArgument)` if a size is negative or the sizes do not add up.
  ControlMesh(std::vector<Vec3> positions, const std::vector<int32_t>& face_sizes,
              std::vector<int32_t> face_indices);

  int32_t num_vertices() const { return static_cast<int32_t>(positions_.size()); }
  int32_t num_faces() const { return static_cast<int32_t>(face_offsets_.size()) - 1; }

  /// Control point indices of face `f` (0 <= f < num_faces()).
  std::span<const int32_t> face(int32_t f) const {
    return {face_indices_.data() + face_offsets_[f],
            static_cast<size_t>(face_offsets_[f + 1] - face_offsets_[f])};
  }
  int32_t face_size(int32_t f) const { return face_offsets_[f + 1] - face_offsets_[f]; }

  /// Rest positions, one per control point (#V).
  const std::vector<Vec3>& positions() const { return positions_; }
  /// Mutable positions (the topology cannot be changed).
  std::vector<Vec3>& positions() { return positions_; }

  /// All face indices back to back; face f starts at face_offsets()[f] (size #F + 1).
  const std::vector<int32_t>& face_indices() const { return face_indices_; }
  const std::vector<int32_t>& face_offsets() const { return face_offsets_; }
  /// Size of every face (#F).
  std::vector<int32_t> face_sizes() const;

  const std::vector<Crease>& creases() const { return creases_; }
  std::vector<Crease>& creases() { return creases_; }
  const std::vector<Corner>& corners() const { return corners_; }
  std::vector<Corner>& corners() { return corners_; }
  /// True if the mesh carries sharpness tags (which the binary wire format cannot send).
  bool has_sharpness() const { return !creases_.empty() || !corners_.empty(); }

  BoundaryMode boundary() const { return boundary_; }
  void set_boundary(BoundaryMode mode) { boundary_ = mode; }

  /// True if every face has four control points.
  bool all_quads() const;
  /// Axis-aligned bounding box of the control points.
  void bounding_box(Vec3& out_min, Vec3& out_max) const;
  /// Length of the bounding box diagonal (the mesh's "size"); 0 for an empty mesh.
  double bounding_diagonal() const;

  /// Same topology, tags and positions exactly.
  bool operator==(const ControlMesh& other) const;

 private:
  std::vector<Vec3> positions_;
  std::vector<int32_t> face_offsets_{0};
  std::vector<int32_t> face_indices_;
  std::vector<Crease> creases_;
  std::vector<Corner> corners_;
  BoundaryMode boundary_ = BoundaryMode::kEdgeAndCorner;
};

}  // namespace softshell
