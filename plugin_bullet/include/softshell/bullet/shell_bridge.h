#pragma once
/// \file
/// \brief `ShellBridge`: softshell shells inside a Bullet world. Rigid bodies that hit a shell
/// push on it (contact impulses become forces on its control points, sent asynchronously to any
/// `Session`), and the shell's collision mesh follows the deformation the server computes. By
/// default the bridge takes part in the object's shared hold state (PROTOCOL.md version 2): its
/// floor and its contacts are two holds among those of other clients (users' hands, other worlds).

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "softshell/event_subscription.h"
#include "softshell/executor.h"
#include "softshell/hold.h"

#include <LinearMath/btTransform.h>

#include "softshell/bullet/collision_mesh.h"
#include "softshell/bullet/contact_forces.h"
#include "softshell/bullet/floor_constraints.h"
#include "softshell/bullet/latest_wins_channel.h"
#include "softshell/control_mesh.h"
#include "softshell/deformation.h"
#include "softshell/material.h"
#include "softshell/result.h"
#include "softshell/session.h"

class btCollisionObject;
class btDiscreteDynamicsWorld;

namespace softshell::bullet {

/// How a shell takes part in its object's hold state (PROTOCOL.md version 2).
struct ShellHolds {
  /// True: the shell's supports and floor are one hold (`<name>.floor`, put once by `add_shell`)
  /// and its contact forces another (`<name>.contacts`, each change a new version, latest wins),
  /// solved together with every other live hold of the object; the collision mesh follows the
  /// object's hold-state results, whoever caused them (the bridge subscribes to its events).
  /// False: each frame's forces go out with the supports as a request solved alone
  /// (`POST .../results`, version 1: the newest request from any client overrides the others).
  bool enabled = true;
  /// Prefix of the hold ids (1 to 55 characters of [A-Za-z0-9._-]). Two bridges (or two shells)
  /// on one object need different names; empty = "bullet-" and 8 random hex digits.
  std::string name;
  /// Lease of the holds (more than 0, at most 600 s): how long they outlive a bridge that stops
  /// updating without being destroyed (a crash). Renewed while `update()` is called.
  std::chrono::milliseconds ttl{3000};
};

/// Everything configurable about one shell in a Bullet world (units: the world's, which must be the
/// shell's length unit; forces in N when lengths are metres and masses kilograms).
struct ShellSettings {
  /// Tessellation level (0..8) and triangle margin of the collision mesh.
  CollisionMeshSettings mesh;
  /// Contact threshold, friction on/off, force scale and minimum contact force.
  ContactSettings contacts;
  /// Most deformation requests per second (wall clock, >= 0; 0 = unlimited). Frames in between
  /// replace the waiting request (latest wins), so a slower rate never delays the newest forces
  /// by more than one interval.
  double max_request_rate = 60.0;
  /// Time constant (s of simulated time, >= 0) with which the forces sent follow the contact
  /// forces: exponential smoothing per Bullet step. 0 sends every frame's own contact forces.
  double response_time = 0.1;
  /// Lengthen the time constant where the coupling needs it to stay stable. The shell is quasi-
  /// static and its shape lags the forces, so a body resting on it feeds back on itself: when the
  /// surface sinks by ds in one step the body's contact impulse changes by m ds / dt. With the
  /// shell's compliance C at the load (m/N, measured from each result: f.u / |sum f|^2) and the
  /// heaviest dynamic body m on it, smoothing with alpha <= dt^2 / (4 m C) per step keeps the loop
  /// gain below 1/4 (time constant about 4 m C / dt). At rest the smoothed force equals the raw one.
  bool stabilize = true;
  /// A frame whose control-point forces differ from the last submitted ones by less than this
  /// (relative L2 norm, >= 0) is not submitted. 0 submits every frame whose forces changed at all.
  double min_relative_change = 0.01;
  /// Supports and constant loads sent with every request: fixed control points (vertex
  /// constraints), Lagrange and limit constraints, forces, surface load, pressure. The shell needs
  /// enough of them (or the floor) to be determined; the server answers kUnprocessable otherwise.
  /// The frame's contact forces are added to `supports.forces` (with holds: `supports` and the
  /// floor are the floor hold, the contact forces alone the contacts hold).
  DeformationRequest supports;
  /// Holds or requests (see `ShellHolds`).
  ShellHolds holds;
  /// The model everything the bridge sends is solved with (its holds, or its requests without
  /// holds; `supports.model` is replaced by it). kNonlinear for bodies that bend the shell far
  /// (beyond a fraction of its thickness): large displacements without the linear model's
  /// stretching, at the cost of Newton iterations per result. A hold state is nonlinear while any
  /// live hold of it asks for it, so one nonlinear bridge makes the object's state nonlinear.
  DeformationModel model = DeformationModel::kLinear;
  /// The ground plane; touching parts are held there (added to the supports).
  FloorSettings floor;
  /// Placement of the shell's local frame (its control points' frame) in the world.
  btTransform transform = btTransform::getIdentity();
  double friction = 0.5;      ///< Bullet friction coefficient of the shell's surface (>= 0)
  double restitution = 0.0;   ///< Bullet restitution of the shell's surface (0..1)
  /// Bullet broadphase filter group and mask of the shell's collision object.
  int collision_group = 2;    ///< btBroadphaseProxy::StaticFilter
  int collision_mask = ~2;    ///< everything but other static objects
  /// Move the collision mesh to a new result in a task on the bridge's executor (limit evaluation
  /// and BVH refit into the hidden half of the double-buffered `CollisionMesh`), so the physics thread
  /// only swaps shapes: a result then shows one or more steps after it arrived. False does the
  /// whole update inside `update()`.
  bool background_mesh_update = true;
};

/// A shell's handle: an index and a generation, so a handle of a removed shell is detected.
struct ShellId {
  uint32_t index = 0;
  uint32_t generation = 0;  ///< 0 is never a valid generation
  bool operator==(const ShellId&) const = default;
};

/// Counters and the latest state of one shell.
struct ShellStats {
  uint64_t updates = 0;             ///< `ShellBridge::update` calls seen
  int32_t contacts = 0;             ///< contact points in the last update
  Vec3 contact_force = Vec3::Zero();  ///< total contact force of the last update (world frame, N)
  double compliance = 0.0;          ///< measured compliance at the load, f.u / |sum f|^2 (length unit / N; 0 = unknown)
  double time_constant = 0.0;       ///< smoothing time constant used in the last update (s)
  uint64_t unchanged_frames = 0;    ///< frames not submitted because their forces barely changed
  uint64_t results_applied = 0;     ///< results the collision mesh was updated to
  uint32_t res_id = 0;              ///< the result the collision mesh shows (0 = rest shape)
  /// With holds: the hold versions of the result shown (every client's, this bridge's included).
  HoldVersions shown_holds;
  /// With holds: results shown that came from the object's events rather than the answers to
  /// this bridge's own puts (other clients' changes, or results the answers had skipped).
  uint64_t results_from_events = 0;
  ChannelStats channel;             ///< requests submitted, sent, replaced, completed, failed
  std::optional<Error> last_error;  ///< the session's last error (cleared by the next result)
};

/// What one `update` did, over all shells.
struct UpdateReport {
  int32_t contacts = 0;         ///< contact points read
  int32_t submitted = 0;        ///< frames submitted (sent or made pending)
  int32_t results_applied = 0;  ///< collision meshes moved to a new result
  int32_t errors = 0;           ///< errors the session answered
};

/// Shells in a `btDiscreteDynamicsWorld`.
///
/// With holds (`ShellHolds`, the default) the requests below are the contents of the shell's
/// contacts hold (its forces only; the supports and the floor are the floor hold, put by
/// `add_shell`), sent with `put_hold_async` through the same latest-wins channel (its renewals go
/// out from `update()`), and the collision mesh moves to the newest hold-state result of the
/// object, from the answers or from the object's events: the shape the bodies collide with
/// includes other clients' holds. Both holds are released when the shell is removed or the
/// bridge destroyed (one blocking round trip each).
///
/// Each shell is a static collision object whose shape is a `CollisionMesh` (a
/// `btBvhTriangleMeshShape` over the SDK tessellation). Call `update()` after every
/// `stepSimulation`: it reads the contact manifolds of every shell, turns each contact point's
/// impulse into a force (impulse / Bullet's internal time step, normal plus friction) at the
/// contact's `(face, u, v)`, spreads the frame's forces over the control points with the limit
/// weights, smooths them over `response_time` (see `stabilize`) and submits one request per
/// shell (supports + these forces) to a `LatestWinsChannel`, which sends it without blocking.
/// Results that arrived are applied: the collision mesh moves to the deformed limit surface and
/// its BVH is refitted; cached contacts of the shell are dropped so that the next step finds the
/// new surface.
///
/// The shell model is linear and every result is a displacement from the rest shape, so each
/// request carries the current forces, not an accumulation. Bodies resting on a shell keep
/// pressing on it, so it stays dented while they lie there and springs back when they leave (the
/// forces fade out, then one request without contact forces). Only dynamic bodies push: Bullet
/// makes no contacts between a static shell and kinematic or static objects.
///
/// With `background_mesh_update` (the default) the new limit surface is evaluated and the BVH
/// refitted in a task on the host's `Executor` (one task at a time per bridge, so the work stays
/// in order), into the hidden half of the shell's double-buffered collision mesh; `update()` then
/// only swaps the collision object's shape.
///
/// Ownership: the world is not owned and must outlive the bridge (the destructor waits for the
/// bridge's running task and removes the shells' collision objects from the world). Sessions and
/// the executor are shared. Thread-safety: call every member from the thread that steps the
/// world, between `stepSimulation` calls (the task never touches what Bullet or that thread use).
class ShellBridge {
 public:
  /// `executor`: where the background mesh updates run (default: the process-wide pool). An
  /// `InlineExecutor` runs them inside `update()`, like `background_mesh_update = false`.
  explicit ShellBridge(btDiscreteDynamicsWorld& world, std::shared_ptr<Executor> executor = default_executor());
  ~ShellBridge();
  ShellBridge(const ShellBridge&) = delete;
  ShellBridge& operator=(const ShellBridge&) = delete;

  /// Adds a shell for a geometry the session already holds; `mesh` must be the control mesh it
  /// was uploaded with (its rest shape, in the shell's local frame). Builds the tessellation,
  /// the Bullet shape and the floor constraints. Without holds there is no network traffic; with
  /// holds it puts the floor hold (if the supports and the floor hold anything; blocking: one
  /// solve) and subscribes to the object's events, and fails with the server's error (kConflict
  /// naming the holds the floor contradicts, kUnprocessable if the hold state is undetermined with
  /// it). kInvalidArgument for bad settings or a mesh the limit evaluator rejects.
  Result<ShellId> add_shell(std::shared_ptr<Session> session, const GeomId& geometry, const ControlMesh& mesh,
                            const ShellSettings& settings = {});

  /// Uploads `mesh` with `material` through the session (blocking, once), then adds it.
  Result<ShellId> add_shell(std::shared_ptr<Session> session, const ControlMesh& mesh, const Material& material,
                            const ShellSettings& settings = {}, std::string_view name_space = "");

  /// Removes a shell from the world. A request still in flight is finished by the session and
  /// ignored. kNotFound for a stale handle.
  Result<void> remove_shell(ShellId shell);

  /// True if `shell` names a shell of this bridge.
  bool valid(ShellId shell) const;
  /// Handles of all shells, in the order added.
  std::vector<ShellId> shells() const;

  /// Call after each `stepSimulation`: reads contacts, submits forces, applies arrived results.
  /// Never blocks on a session. Errors from a session are counted and kept in `stats`.
  UpdateReport update();

  /// Blocks until every shell's requests are answered and applied, or `timeout` passes
  /// (kUnavailable). For tests, tools and loading screens, not for the physics loop.
  Result<void> wait_idle(std::chrono::milliseconds timeout);

  // --- per shell; every accessor throws Exception(kNotFound) for a stale handle ---

  /// The shell's Bullet collision object (owned by the bridge, in the world).
  btCollisionObject& collision_object(ShellId shell);
  /// The collision mesh: rendering buffers (`positions`, `normals`, `indices`, `version`) and
  /// the tessellation.
  const CollisionMesh& collision_mesh(ShellId shell) const;
  /// Control point positions of the shape shown (rest + displacement of result `stats().res_id`).
  const std::vector<Vec3>& control_positions(ShellId shell) const;
  /// Contacts read by the last `update`.
  const std::vector<ContactForce>& contacts(ShellId shell) const;
  /// The constraints the floor adds to every request (none if the floor is off or not touched).
  const DeformationRequest& floor(ShellId shell) const;
  /// The ids of the shell's floor and contacts holds ("" without holds). The floor hold exists
  /// only if the supports and the floor hold something; the contacts hold from the first frame
  /// with contacts on.
  const std::string& floor_hold_id(ShellId shell) const;
  const std::string& contacts_hold_id(ShellId shell) const;
  /// The request sent most recently (with holds: the contacts hold's contents), or nullptr.
  const DeformationRequest* last_sent_request(ShellId shell) const;
  /// The geometry and its session.
  const GeomId& geometry(ShellId shell) const;
  const ShellSettings& settings(ShellId shell) const;
  ShellStats stats(ShellId shell) const;

 private:
  struct Shell;
  Shell& get(ShellId shell) const;
  void receive(Shell& shell, ChannelAnswer& answer, UpdateReport& report);
  void commit_prepared(Shell& shell, UpdateReport& report);
  void show(Shell& shell, uint32_t res_id, HoldVersions holds, UpdateReport& report);
  void apply(Shell& shell, DeformationResult result, HoldVersions holds, UpdateReport& report);
  void follow_events(Shell& shell, UpdateReport& report);
  bool busy(const Shell& shell) const;
  bool runnable_locked() const;
  void start_work();
  void work();

  btDiscreteDynamicsWorld& world_;
  std::vector<std::unique_ptr<Shell>> slots_;
  std::vector<uint32_t> generations_;
  std::vector<double> max_mass_;  // scratch of update()
  // The task that prepares collision meshes (at most one runs: working_); mutex_ guards slots_
  // changes and the job states, done_ signals a finished job or the task's end.
  std::shared_ptr<Executor> executor_;
  mutable std::mutex mutex_;
  std::condition_variable done_;
  bool stopping_ = false;
  bool working_ = false;
};

}  // namespace softshell::bullet
