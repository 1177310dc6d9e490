#pragma once
/// \file
/// \brief Checks that a control mesh can be subdivided and simulated, with messages that say which
/// face or control point is wrong.

#include <cstdint>
#include <string>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/result.h"

namespace softshell {

/// What is wrong. The first group makes a mesh malformed (HTTP 400), the second unusable for the
/// simulation (HTTP 422).
enum class MeshIssueKind : uint8_t {
  // malformed (kInvalidArgument)
  kEmpty,             ///< no control points or no faces
  kFaceTooSmall,      ///< a face with fewer than 3 control points
  kIndexOutOfRange,   ///< a face or tag refers to a control point that does not exist
  kRepeatedIndex,     ///< a face uses the same control point twice
  kNonFinite,         ///< a coordinate is NaN or infinite
  kBadTag,            ///< a crease/corner tag with a negative or non-finite sharpness, or a crease on a non-edge
  // unusable (kUnprocessable)
  kNonManifoldEdge,          ///< an edge shared by more than two faces
  kNonManifoldVertex,        ///< faces that meet only at a control point (not through an edge there)
  kInconsistentOrientation,  ///< two faces traverse their shared edge in the same direction
  kZeroAreaFace,             ///< a face whose area is (numerically) zero
  kUnusedVertex,             ///< a control point used by no face (it would have no stiffness)
};

/// One problem found in a mesh.
struct MeshIssue {
  MeshIssueKind kind;
  int32_t face = -1;    ///< the face concerned, or -1
  int32_t vertex = -1;  ///< the control point concerned, or -1
  std::string message;  ///< for a person, e.g. "face 12 uses control point 7 twice"
  ErrorCode code() const;
};

/// Every problem found (at most `max_issues` of them), malformed ones first. An empty list means
/// the mesh can be subdivided and simulated. Never throws on any input.
std::vector<MeshIssue> find_mesh_issues(const ControlMesh& mesh, size_t max_issues = 64);

/// Ok, or the first issue as an error (kInvalidArgument or kUnprocessable) whose message also says
/// how many more issues there are.
Result<void> validate_mesh(const ControlMesh& mesh);

}  // namespace softshell
