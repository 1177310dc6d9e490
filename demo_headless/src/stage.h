#pragma once
// How the demo's script adapts to the object: its size, its up axis, its parts, how each part is
// held (resting on the floor, or pinned where it cannot rest), and where a hand can reach it.

#include <optional>
#include <string>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/deformation.h"
#include "softshell/limit_evaluator.h"
#include "softshell/picking.h"
#include "softshell/tessellation.h"

namespace softshell::demo {

/// What the master client shows: the shape of the newest result, for picking and drawing. (The
/// picker refers to the tessellation, so the view stays where it is constructed.)
struct View {
  View(const ControlMesh& mesh, int level);
  View(const View&) = delete;
  View& operator=(const View&) = delete;
  void show(const std::vector<Vec3>& positions);

  LimitEvaluator evaluator;
  Tessellation surface;
  Picker picker;
  std::vector<Vec3> control;                  // control points of the shape shown
  std::vector<Vec3> rest_vertices, rest_normals;  // the tessellation at rest
};

/// A connected piece of the mesh.
struct Part {
  double area = 0.0;
  Vec3 centroid = Vec3::Zero();               ///< of its rest limit surface
  Vec3 lo = Vec3::Zero(), hi = Vec3::Zero();  ///< bounds of its rest limit surface
  int control_points = 0;
  /// How it is held: resting on the floor (limit points where it touches, with their tangent
  /// planes if they alone would let it rock), fixed (a part of at most kFixedPart control points
  /// is too coarse to bend: every control point held), or pinned at three points (statically
  /// determinate: 3 + 2 + 1 displacement components, so the pins hold it without straining it).
  enum class Hold : uint8_t { kFloor, kFixed, kPins } hold = Hold::kPins;
  bool glued = false;                         ///< floor contacts also hold their tangent planes
  int touching = 0;                           ///< contact points where it touches the floor
  int floor_points = 0, pins = 0;             ///< held: at most kMaxFloorPoints of the contact points
  static constexpr int kFixedPart = 8;
  static constexpr int kMinHandled = 8;       ///< control points the part the hands hold needs
  static constexpr int kMaxFloorPoints = 16;
};

struct Stage {
  int up_axis = 1;
  bool up_detected = true;
  Vec3 up = Vec3::UnitY(), e1 = Vec3::UnitX(), e2 = Vec3::UnitZ();  ///< e1 along the longer horizontal extent
  Vec3 lo = Vec3::Zero(), hi = Vec3::Zero(), centre = Vec3::Zero();  ///< bounds of the rest limit surface
  double size = 0.0;                          ///< bounding diagonal
  double height = 0.0;                        ///< extent along `up`
  double floor_height = 0.0;                  ///< `up` coordinate of the floor (the lowest point)
  double contact_tolerance = 0.0;             ///< surface this close to the floor touches it
  std::vector<int32_t> part_of_face;
  std::vector<Part> parts;
  int main_part = 0;                          ///< the one with the most control points: where the hands go
  DeformationRequest supports;                ///< floor contacts and pins, sent with every request
  std::vector<Vec3> floor_points, pin_points; ///< where they are (rest), for the pictures
  int fixed_parts = 0;
  /// Per rest tessellation vertex: on the main part and away from every support.
  std::vector<char> reachable;

  /// Height above the floor.
  double height_of(const Vec3& p) const { return up.dot(p) - floor_height; }
  /// The reachable rest vertex furthest along `direction` among those whose height lies between
  /// the fractions `band_lo` and `band_hi` of the main part's height range; -1 if there is none.
  int32_t extreme(const std::vector<Vec3>& rest, const Vec3& direction, double band_lo, double band_hi) const;
  char up_name() const { return static_cast<char>('x' + up_axis); }
  /// For the summary, e.g. "rests on the floor at 12 points".
  std::string describe_supports() const;
  int resting_parts() const;
};

/// Adapts the script to `view`'s object at rest. `up_axis` forces the up axis (0, 1, 2).
/// kUnprocessable if no part is fine enough for the hands (fewer than Part::kMinHandled control points).
Stage adapt_to_object(const ControlMesh& mesh, const View& view, std::optional<int> up_axis);

}  // namespace softshell::demo
