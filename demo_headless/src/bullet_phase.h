#pragma once
// The demo's Bullet phase: boxes of different mass dropped on the shell, which dents under them
// through the bridge (plugin_bullet).

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "softshell/deformation.h"
#include "softshell/hold.h"
#include "softshell/session.h"

namespace softshell::demo {

struct Context;

/// What the Bullet world is made of.
struct BulletSetup {
  DeformationRequest supports;   ///< what holds the shell (floor contacts, pins)
  Vec3 up = Vec3::UnitY();       ///< gravity is -9.81 m/s² along it
  double floor_height = 0.0;     ///< the ground plane: up . x = floor_height
  std::vector<Vec3> spots;       ///< where the boxes land (rest surface points)
  std::vector<double> masses;    ///< kg, one per spot
  double half = 0.05;            ///< half edge of the boxes (m)
  int level = 2;                 ///< collision mesh tessellation level
  int steps = 240;               ///< Bullet steps of 1/60 s
  std::string holds_name;        ///< prefix of the bridge's hold ids ("" = a random one)
  double step_ms = 4.167;        ///< wall-clock time per step (4.167: four times real time)
  /// Called after every step with the result the bridge shows and its hold versions.
  std::function<void(uint32_t res_id, const HoldVersions& holds)> each_step;
  /// Called once the steps are done and the bridge is idle, while its holds still live.
  std::function<void()> before_release;
};

struct BulletPhaseResult {
  int contacts = 0;              ///< contact points seen over all steps
  int requests = 0;              ///< deformation requests the bridge sent
  uint32_t res_id = 0;           ///< the last result shown (0: none)
  std::vector<Vec3> positions;   ///< its control points (empty if none)
  struct Body {
    std::array<Vec3, 8> corners; ///< where it came to rest
    double mass = 0.0;           ///< kg
    bool on_shell = false;       ///< touching the shell at the end
  };
  std::vector<Body> bodies;
};

/// Every result the bridge shows: its id and control points.
using OnResult = std::function<void(uint32_t res_id, const std::vector<Vec3>& positions)>;

/// Runs the Bullet world on the shell `id` (uploaded from `mesh`).
BulletPhaseResult run_bullet_world(const std::shared_ptr<Session>& session, const GeomId& id, const ControlMesh& mesh,
                                   const BulletSetup& setup, const OnResult& on_result);

/// Flat spots on top of the object where boxes can land (rest surface points; empty if none)
/// and the boxes' half edge: `setup.spots`, `setup.half`, `up`, the floor and the level.
BulletSetup bullet_setup(const Context& c);

/// The phase in the script: picks flat spots on top, chooses masses that dent the shell inside
/// the linear model's range (from a probe), runs the world, and records what happened.
void bullet_phase(Context& c);

}  // namespace softshell::demo
