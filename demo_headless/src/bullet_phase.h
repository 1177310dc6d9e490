#pragma once
// The demo's Bullet phase: rigid bodies of different mass dropped on the shell, which dents
// under them through the bridge (plugin_bullet).

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "softshell/interaction.h"
#include "softshell/picking.h"
#include "softshell/session.h"

namespace softshell::demo {

struct BulletPhaseResult {
  int bodies = 0;
  int contacts = 0;              ///< contact points seen over all steps
  int requests = 0;              ///< deformation requests the bridge sent
  double max_deflection = 0.0;   ///< largest limit-surface displacement of a received result (m)
  std::vector<Vec3> positions;   ///< control points of the last result shown (empty if none)
  struct BodyMesh {              ///< the bodies where they came to rest, for the picture
    std::vector<Vec3> vertices, normals;
    std::vector<std::array<int32_t, 3>> triangles;
  };
  std::vector<BodyMesh> body_meshes;
  std::vector<double> masses;    ///< kg, per body
};

/// Runs `steps` Bullet steps of 1/60 s with three boxes (1, 5 and 20 kg) dropped on the shell
/// `id`, held by `floor`, with the ground plane at height `floor_y` (+y up). The boxes start just
/// above the points where vertical rays through `picker` (the rest shape) hit the object's top.
/// `on_result` is called with every result id the bridge shows.
BulletPhaseResult run_bullet_phase(const std::shared_ptr<Session>& session, const GeomId& id,
                                   const ControlMesh& mesh, const FloorContact& floor, double floor_y,
                                   const Picker& picker, int level, int steps,
                                   const std::function<void(uint32_t)>& on_result);

}  // namespace softshell::demo
