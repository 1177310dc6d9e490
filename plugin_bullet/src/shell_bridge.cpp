#include "softshell/bullet/shell_bridge.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <thread>
#include <mutex>
#include <condition_variable>

#include <BulletCollision/BroadphaseCollision/btDispatcher.h>
#include <BulletCollision/CollisionDispatch/btCollisionObject.h>
#include <BulletCollision/CollisionShapes/btBvhTriangleMeshShape.h>
#include <BulletCollision/NarrowPhaseCollision/btPersistentManifold.h>
#include <BulletDynamics/Dynamics/btDiscreteDynamicsWorld.h>
#include <BulletDynamics/Dynamics/btRigidBody.h>

#include "softshell/bullet/force_accumulator.h"
#include "shell_settings.h"
#include "softshell/hold_lease.h"

namespace softshell::bullet {

namespace {

// Smoothing time constant = kStabilityFactor * m * C / dt keeps the per-step loop gain
// alpha * m * C / dt^2 at about 1 / kStabilityFactor (stable below about 1/3).
constexpr double kStabilityFactor = 4.0;

Eigen::Isometry3d to_isometry(const btTransform& t) {
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) out.linear()(r, c) = t.getBasis()[r][c];
    out.translation()[r] = t.getOrigin()[r];
  }
  return out;
}

LatestWinsChannel make_channel(std::shared_ptr<Session> session, const GeomId& geometry, const ShellSettings& s,
                               const std::string& contacts_hold) {
  if (!s.holds.enabled) return LatestWinsChannel(std::move(session), geometry, s.max_request_rate);
  return LatestWinsChannel(std::move(session), geometry, HoldTarget{contacts_hold, s.holds.ttl}, s.max_request_rate);
}

}  // namespace

struct ShellBridge::Shell {
  Shell(std::shared_ptr<Session> session, const GeomId& geometry, const ShellSettings& shell_settings,
        LimitEvaluator evaluator, std::unique_ptr<CollisionMesh> collision_mesh, const std::string& hold_name)
      : settings(shell_settings),
        floor_hold_id(hold_name.empty() ? "" : hold_name + ".floor"),
        contacts_hold_id(hold_name.empty() ? "" : hold_name + ".contacts"),
        mesh(std::move(collision_mesh)),
        channel(make_channel(std::move(session), geometry, shell_settings, contacts_hold_id)),
        frame(evaluator),
        smoothed(evaluator),
        submitted(evaluator),
        rest(evaluator.mesh().positions()) {}

  // Lets go of the holds: contacts first, so the state never keeps loads without the supports.
  ~Shell() {
    events.reset();
    if (channel.hold()) (void)channel.release();
    floor_lease.reset();
  }
  Shell(const Shell&) = delete;
  Shell& operator=(const Shell&) = delete;

  ShellSettings settings;
  std::string floor_hold_id, contacts_hold_id;  // "" without holds
  std::unique_ptr<CollisionMesh> mesh;
  btCollisionObject object;
  LatestWinsChannel channel;
  ForceAccumulator frame;      // this update's contact forces on control points (local frame)
  ForceAccumulator smoothed;   // the forces to send: `frame` smoothed over time
  ForceAccumulator submitted;  // the forces of the last submitted request
  bool submitted_any = false;
  double mass = 0.0;             // heaviest dynamic body of the last frame with contacts (kg)
  double max_point_force = 0.0;  // largest control-point force of the last frame with contacts (N)
  std::vector<Vec3> rest;        // rest control points
  DeformationRequest base;       // supports + floor constraints (without holds: sent with every request)
  DeformationRequest floor;      // the floor's constraints
  std::vector<ContactForce> contacts;
  ShellStats stats;
  // With holds: the floor hold kept alive, the object's results, the newest result id handed to
  // the mesh (queued or shown), so that answers and events never move it back.
  std::unique_ptr<HoldLease> floor_lease;
  std::unique_ptr<EventSubscription> events;
  uint32_t newest = 0;

  // Background mesh update, guarded by ShellBridge::mutex_: a result waiting for the worker
  // (latest wins), the worker preparing the hidden shape, a prepared shape waiting for commit.
  std::optional<DeformationResult> queued;
  HoldVersions queued_holds, preparing_holds, ready_holds;
  bool preparing = false;
  bool ready = false;
  uint32_t ready_res_id = 0;
  std::optional<Error> prepare_error;
};

ShellBridge::ShellBridge(btDiscreteDynamicsWorld& world, std::shared_ptr<Executor> executor)
    : world_(world), executor_(executor ? std::move(executor) : default_executor()) {}

ShellBridge::~ShellBridge() {
  {
    // The running task finishes its job and ends; no new one starts.
    std::unique_lock lock(mutex_);
    stopping_ = true;
    done_.wait(lock, [&] { return !working_; });
  }
  for (auto& slot : slots_) {
    if (slot) world_.removeCollisionObject(&slot->object);
  }
  slots_.clear();  // releases the holds
}

Result<ShellId> ShellBridge::add_shell(std::shared_ptr<Session> session, const GeomId& geometry,
                                       const ControlMesh& mesh, const ShellSettings& settings) {
  return capture([&]() -> ShellId {
    if (!session) fail(ErrorCode::kInvalidArgument, "add_shell needs a session");
    check_settings(settings);
    auto evaluator = LimitEvaluator::create(mesh);
    if (!evaluator) throw Exception(evaluator.error());
    auto collision_mesh = CollisionMesh::create(*evaluator, settings.mesh);
    if (!collision_mesh) throw Exception(collision_mesh.error());

    const std::string hold_name =
        !settings.holds.enabled ? "" : settings.holds.name.empty() ? random_hold_name() : settings.holds.name;
    Session& client = *session;
    auto shell = std::make_unique<Shell>(std::move(session), geometry, settings, *evaluator,
                                         std::move(*collision_mesh), hold_name);
    // Supports: the app's constraints and loads, then the floor.
    shell->base = settings.supports;
    shell->base.model = settings.model;
    if (settings.floor.enabled) {
      auto floor = floor_request(shell->mesh->tessellation(), to_isometry(settings.transform), settings.floor);
      if (!floor) throw Exception(floor.error());
      shell->floor = std::move(*floor);
      auto append = [](auto& to, const auto& from) { to.insert(to.end(), from.begin(), from.end()); };
      append(shell->base.vertex_constraints, shell->floor.vertex_constraints);
      append(shell->base.lagrange_constraints, shell->floor.lagrange_constraints);
      append(shell->base.limit_constraints, shell->floor.limit_constraints);
    }
    if (settings.holds.enabled) {
      // The floor hold first (blocking, once: its refusal is this call's error), then a lease that
      // renews it; then the object's results, the newest at once.
      if (!shell->base.empty()) {
        auto put = client.put_hold(geometry, shell->floor_hold_id, shell->base, settings.holds.ttl);
        if (!put) throw Exception(put.error());
        HoldLeaseOptions lease;
        lease.ttl = settings.holds.ttl;
        shell->floor_lease = std::make_unique<HoldLease>(client, geometry, shell->floor_hold_id, shell->base, lease);
      }
      auto events = client.subscribe(geometry);
      if (!events) throw Exception(events.error());
      shell->events = std::move(*events);
    }

    // The static collision object.
    btCollisionObject& object = shell->object;
    object.setCollisionShape(&shell->mesh->shape());
    object.setWorldTransform(settings.transform);
    object.setCollisionFlags(object.getCollisionFlags() | btCollisionObject::CF_STATIC_OBJECT);
    object.setFriction(static_cast<btScalar>(settings.friction));
    object.setRestitution(static_cast<btScalar>(settings.restitution));

    // A free slot or a new one; generations start at 1.
    std::lock_guard lock(mutex_);
    uint32_t index = 0;
    while (index < slots_.size() && slots_[index]) ++index;
    if (index == slots_.size()) {
      slots_.emplace_back();
      generations_.push_back(0);
    }
    slots_[index] = std::move(shell);
    const uint32_t generation = ++generations_[index];
    world_.addCollisionObject(&slots_[index]->object, settings.collision_group, settings.collision_mask);
    return ShellId{index, generation};
  });
}

Result<ShellId> ShellBridge::add_shell(std::shared_ptr<Session> session, const ControlMesh& mesh,
                                       const Material& material, const ShellSettings& settings,
                                       std::string_view name_space) {
  if (!session) return Error{ErrorCode::kInvalidArgument, "add_shell needs a session"};
  auto uploaded = session->upload(mesh, material, name_space);
  if (!uploaded) return uploaded.error();
  return add_shell(std::move(session), uploaded->id, mesh, settings);
}

bool ShellBridge::valid(ShellId shell) const {
  return shell.generation != 0 && shell.index < slots_.size() && slots_[shell.index] &&
         generations_[shell.index] == shell.generation;
}

ShellBridge::Shell& ShellBridge::get(ShellId shell) const {
  if (!valid(shell)) {
    fail(ErrorCode::kNotFound, "shell handle {" + std::to_string(shell.index) + ", " +
                                   std::to_string(shell.generation) + "} does not name a shell of this bridge");
  }
  return *slots_[shell.index];
}

Result<void> ShellBridge::remove_shell(ShellId shell) {
  return capture([&] {
    Shell& s = get(shell);
    std::unique_ptr<Shell> removed;
    {
      // Wait for the task to leave this shell's mesh alone, then take it out of the slots.
      std::unique_lock lock(mutex_);
      done_.wait(lock, [&] { return !s.preparing; });
      removed = std::move(slots_[shell.index]);
    }
    world_.removeCollisionObject(&removed->object);
  });
}

std::vector<ShellId> ShellBridge::shells() const {
  std::vector<ShellId> out;
  for (uint32_t i = 0; i < slots_.size(); ++i) {
    if (slots_[i]) out.push_back(ShellId{i, generations_[i]});
  }
  return out;
}

// A shell with a result waiting whose last prepared shape was committed (a prepared shape is
// committed before the next one is prepared over it).
bool ShellBridge::runnable_locked() const {
  for (const auto& slot : slots_) {
    if (slot && slot->queued && !slot->preparing && !slot->ready) return true;
  }
  return false;
}

// Posts the task unless one runs (it then picks the new job up) or nothing is runnable.
void ShellBridge::start_work() {
  {
    std::lock_guard lock(mutex_);
    if (working_ || stopping_ || !runnable_locked()) return;
    working_ = true;
  }
  executor_->post([this] { work(); });
}

void ShellBridge::work() {
  std::unique_lock lock(mutex_);
  for (;;) {
    Shell* job = nullptr;
    if (!stopping_) {
      for (auto& slot : slots_) {
        if (slot && slot->queued && !slot->preparing && !slot->ready) {
          job = slot.get();
          break;
        }
      }
    }
    if (!job) {
      working_ = false;
      done_.notify_all();
      return;
    }
    DeformationResult result = std::move(*job->queued);
    job->queued.reset();
    job->preparing_holds = std::move(job->queued_holds);
    job->preparing = true;
    lock.unlock();

    // The heavy part, while Bullet keeps using the visible shape.
    auto prepared = capture([&] { job->mesh->prepare(std::move(result.positions)); });

    lock.lock();
    job->preparing = false;
    job->ready = prepared.ok();
    job->ready_res_id = result.res_id;
    job->ready_holds = std::move(job->preparing_holds);
    if (!prepared.ok()) job->prepare_error = prepared.error();
    done_.notify_all();
  }
}

void ShellBridge::show(Shell& shell, uint32_t res_id, HoldVersions holds, UpdateReport& report) {
  // The collision object now uses the other shape of the double buffer.
  shell.object.setCollisionShape(&shell.mesh->shape());
  shell.stats.res_id = res_id;
  shell.stats.shown_holds = std::move(holds);
  ++shell.stats.results_applied;
  ++report.results_applied;
  world_.updateSingleAabb(&shell.object);

  // Bullet keeps contact points in the shell's local frame and refreshes them from the objects'
  // transforms only; a static shell never moves, so after a deformation its cached points would
  // still hold bodies on the old surface. Dropping them lets the next step's narrowphase find the
  // contacts on the new surface.
  btDispatcher& dispatcher = *world_.getDispatcher();
  for (int m = 0; m < dispatcher.getNumManifolds(); ++m) {
    btPersistentManifold* manifold = dispatcher.getManifoldByIndexInternal(m);
    const btCollisionObject* other = nullptr;
    if (manifold->getBody0() == &shell.object) other = manifold->getBody1();
    if (manifold->getBody1() == &shell.object) other = manifold->getBody0();
    if (!other || manifold->getNumContacts() == 0) continue;
    dispatcher.clearManifold(manifold);
    // A sleeping body gets no new contacts against a static object: wake it so that it follows
    // the new surface (and keeps pressing on it). Awake bodies keep their sleep timers.
    if (!other->isStaticOrKinematicObject() && other->getActivationState() == ISLAND_SLEEPING) {
      const_cast<btCollisionObject*>(other)->activate(true);  // Bullet hands out const bodies here
    }
  }
}

void ShellBridge::receive(Shell& shell, ChannelAnswer& answer, UpdateReport& report) {
  if (!answer.result.ok()) {
    shell.stats.last_error = answer.result.error();
    ++report.errors;
    return;
  }
  DeformationResult& result = *answer.result;
  if (result.positions.size() != shell.rest.size()) {
    shell.stats.last_error = Error{ErrorCode::kInternal, "the session returned " +
                                                             std::to_string(result.positions.size()) +
                                                             " positions for a mesh of " +
                                                             std::to_string(shell.rest.size())};
    ++report.errors;
    return;
  }

  // Compliance at the load: f.u / |sum f|^2 over the request's control-point forces (the virtual
  // work of the contact forces at their points, since f_A = sum_i N_A(p_i) f_i).
  Vec3 total = Vec3::Zero();
  double virtual_work = 0.0;
  for (const PointForce& f : answer.request.forces) {
    if (f.index < 0 || static_cast<size_t>(f.index) >= shell.rest.size()) continue;
    total += f.force;
    virtual_work += f.force.dot(result.positions[static_cast<size_t>(f.index)] - shell.rest[static_cast<size_t>(f.index)]);
  }
  if (total.squaredNorm() > 0.0 && std::isfinite(virtual_work)) {
    shell.stats.compliance = std::max(0.0, virtual_work) / total.squaredNorm();
  }
  shell.stats.last_error.reset();
  // With holds, the object's events may have brought this result (or a newer one) already.
  if (shell.settings.holds.enabled && result.res_id <= shell.newest) return;
  apply(shell, std::move(result), answer.holds.value_or(HoldVersions{}), report);
}

void ShellBridge::apply(Shell& shell, DeformationResult result, HoldVersions holds, UpdateReport& report) {
  shell.newest = std::max(shell.newest, result.res_id);
  if (shell.settings.background_mesh_update) {
    // Hand the positions to the task (replacing a result it has not started on).
    {
      std::lock_guard lock(mutex_);
      shell.queued = std::move(result);
      shell.queued_holds = std::move(holds);
    }
    start_work();
    return;
  }
  auto applied = capture([&] { shell.mesh->update(std::move(result.positions)); });
  if (!applied) {
    shell.stats.last_error = applied.error();
    ++report.errors;
    return;
  }
  show(shell, result.res_id, std::move(holds), report);
}

// The object's newest hold-state result, whoever changed the holds. Results of requests solved
// alone (no hold versions) are not the state this shell takes part in and are left out.
void ShellBridge::follow_events(Shell& shell, UpdateReport& report) {
  if (!shell.events) return;
  std::optional<HeldResult> event = shell.events->poll();
  if (!event && shell.events->state() == FeedState::kFailed) {
    shell.stats.last_error = shell.events->error();
    ++report.errors;
    shell.events.reset();  // the answers to the bridge's own puts still move the mesh
    return;
  }
  if (!event || !event->holds || event->result.res_id <= shell.newest) return;
  if (event->result.positions.size() != shell.rest.size()) {
    shell.stats.last_error = Error{ErrorCode::kInternal, "an event brought " + std::to_string(event->result.positions.size()) +
                                                             " positions for a mesh of " + std::to_string(shell.rest.size())};
    ++report.errors;
    return;
  }
  ++shell.stats.results_from_events;
  apply(shell, std::move(event->result), std::move(*event->holds), report);
}

void ShellBridge::commit_prepared(Shell& shell, UpdateReport& report) {
  std::optional<uint32_t> res_id;
  HoldVersions holds;
  {
    std::lock_guard lock(mutex_);
    if (shell.prepare_error) {
      shell.stats.last_error = std::move(shell.prepare_error);
      shell.prepare_error.reset();
      ++report.errors;
    }
    if (shell.ready && !shell.preparing && shell.mesh->commit()) {
      shell.ready = false;
      res_id = shell.ready_res_id;
      holds = std::move(shell.ready_holds);
    }
  }
  if (res_id) {
    start_work();  // a result queued meanwhile can be prepared now
    show(shell, *res_id, std::move(holds), report);
  }
}

bool ShellBridge::busy(const Shell& shell) const {
  std::lock_guard lock(mutex_);
  return shell.queued.has_value() || shell.preparing || shell.ready;
}

UpdateReport ShellBridge::update() {
  UpdateReport report;
  const auto now = LatestWinsChannel::Clock::now();
  const double time_step = static_cast<double>(world_.getSolverInfo().m_timeStep);

  // Start every shell's frame; shapes prepared in the background since the last step go live.
  max_mass_.assign(slots_.size(), 0.0);  // heaviest dynamic body touching each shell (kg)
  for (auto& slot : slots_) {
    if (!slot) continue;
    slot->contacts.clear();
    slot->frame.clear();
    ++slot->stats.updates;
  }

  // One pass over the manifolds; shells are few, so a linear lookup per manifold is cheapest.
  btDispatcher& dispatcher = *world_.getDispatcher();
  ContactForce contact;
  for (int m = 0; m < dispatcher.getNumManifolds(); ++m) {
    const btPersistentManifold* manifold = dispatcher.getManifoldByIndexInternal(m);
    if (manifold->getNumContacts() == 0) continue;
    for (size_t k = 0; k < slots_.size(); ++k) {
      auto& slot = slots_[k];
      if (!slot) continue;
      const bool body0 = manifold->getBody0() == &slot->object;
      if (!body0 && manifold->getBody1() != &slot->object) continue;
      contact.other = body0 ? manifold->getBody1() : manifold->getBody0();
      if (const btRigidBody* body = btRigidBody::upcast(contact.other); body && body->getInvMass() > 0) {
        max_mass_[k] = std::max(max_mass_[k], 1.0 / static_cast<double>(body->getInvMass()));
      }
      for (int p = 0; p < manifold->getNumContacts(); ++p) {
        if (contact_force(manifold->getContactPoint(p), body0, slot->object, *slot->mesh, time_step,
                          slot->settings.contacts, contact)) {
          slot->frame.add(contact.point, contact.local_force);
          slot->contacts.push_back(contact);
        }
      }
    }
  }

  for (size_t k = 0; k < slots_.size(); ++k) {
    if (!slots_[k]) continue;
    Shell& shell = *slots_[k];
    report.contacts += static_cast<int32_t>(shell.contacts.size());
    shell.stats.contacts = static_cast<int32_t>(shell.contacts.size());
    shell.stats.contact_force.setZero();
    for (const ContactForce& c : shell.contacts) shell.stats.contact_force += c.force;

    // Smooth the frame's forces (time constant: the app's, or longer where stability needs it).
    // The heaviest body of the last frame with contacts sets the pace: a body that bounces off
    // for a step still does while it comes back.
    if (!shell.contacts.empty()) shell.mass = max_mass_[k];
    double tau = shell.settings.response_time;
    if (shell.settings.stabilize && time_step > 0.0) {
      tau = std::max(tau, kStabilityFactor * shell.mass * shell.stats.compliance / time_step);
    }
    shell.stats.time_constant = tau;
    const double alpha = (tau > 0.0 && time_step > 0.0) ? -std::expm1(-time_step / tau) : 1.0;
    if (!shell.frame.empty()) {
      shell.max_point_force = 0.0;
      for (int32_t i : shell.frame.touched()) {
        shell.max_point_force = std::max(shell.max_point_force, shell.frame.forces()[static_cast<size_t>(i)].norm());
      }
    }
    // Smoothed forces that fade out (where contacts left) are dropped once below a small fraction
    // of the largest force of the last frame with contacts: 1e-6 while contacts go on, 1e-3 after
    // the last one, so the shell comes back to rest in a few time constants.
    const double fade = shell.frame.empty() ? 1e-3 : 1e-6;
    shell.smoothed.blend_toward(shell.frame, alpha, fade * shell.max_point_force);

    // Submit unless it repeats the last submitted forces (nothing before the first contact). Gaining
    // or losing all forces always counts as a change.
    const bool same_emptiness = shell.smoothed.empty() == shell.submitted.empty();
    const bool unchanged =
        shell.submitted_any ? same_emptiness && shell.smoothed.relative_difference(shell.submitted) <=
                                                    shell.settings.min_relative_change
                            : shell.smoothed.empty();
    if (unchanged) {
      ++shell.stats.unchanged_frames;
    } else {
      // With holds the supports and the floor are a hold of their own: only the forces change.
      DeformationRequest request = shell.settings.holds.enabled ? DeformationRequest{} : shell.base;
      request.model = shell.settings.model;
      shell.smoothed.append_to(request.forces);
      shell.channel.submit(std::move(request), now);
      shell.submitted.assign(shell.smoothed);
      shell.submitted_any = true;
      ++report.submitted;
    }

    // Results that arrived; the pending request goes out when the rate allows. Shapes the worker
    // has prepared go live.
    if (auto answer = shell.channel.poll(now)) receive(shell, *answer, report);
    follow_events(shell, report);
    if (shell.settings.background_mesh_update) commit_prepared(shell, report);
    shell.stats.channel = shell.channel.stats();
  }
  return report;
}

Result<void> ShellBridge::wait_idle(std::chrono::milliseconds timeout) {
  const auto deadline = LatestWinsChannel::Clock::now() + timeout;
  UpdateReport report;
  for (;;) {
    bool idle = true;
    for (auto& slot : slots_) {
      if (!slot) continue;
      Shell& shell = *slot;
      const auto now = LatestWinsChannel::Clock::now();
      if (auto answer = shell.channel.poll(now)) receive(shell, *answer, report);
      follow_events(shell, report);
      commit_prepared(shell, report);
      shell.stats.channel = shell.channel.stats();
      if (shell.channel.depth() > 0 || busy(shell)) idle = false;
    }
    if (idle) return {};
    if (LatestWinsChannel::Clock::now() >= deadline) {
      return Error{ErrorCode::kUnavailable, "ShellBridge::wait_idle: requests still in flight after the timeout"};
    }
    // Wait a little for a request in flight or the mesh task; a rate-limited pending request waits
    // for its time.
    bool waited = false;
    for (auto& slot : slots_) {
      if (slot && slot->channel.in_flight()) {
        (void)slot->channel.wait(std::chrono::milliseconds(1));
        waited = true;
        break;
      }
    }
    if (!waited) {
      std::unique_lock lock(mutex_);
      done_.wait_for(lock, std::chrono::microseconds(500));
    }
  }
}

btCollisionObject& ShellBridge::collision_object(ShellId shell) { return get(shell).object; }
const CollisionMesh& ShellBridge::collision_mesh(ShellId shell) const { return *get(shell).mesh; }
const std::vector<Vec3>& ShellBridge::control_positions(ShellId shell) const {
  return get(shell).mesh->control_positions();
}
const std::vector<ContactForce>& ShellBridge::contacts(ShellId shell) const { return get(shell).contacts; }
const DeformationRequest& ShellBridge::floor(ShellId shell) const { return get(shell).floor; }
const std::string& ShellBridge::floor_hold_id(ShellId shell) const { return get(shell).floor_hold_id; }
const std::string& ShellBridge::contacts_hold_id(ShellId shell) const { return get(shell).contacts_hold_id; }
const DeformationRequest* ShellBridge::last_sent_request(ShellId shell) const {
  return get(shell).channel.last_sent();
}
const GeomId& ShellBridge::geometry(ShellId shell) const { return get(shell).channel.geometry(); }
const ShellSettings& ShellBridge::settings(ShellId shell) const { return get(shell).settings; }
ShellStats ShellBridge::stats(ShellId shell) const {
  const Shell& s = get(shell);
  ShellStats out = s.stats;
  out.channel = s.channel.stats();
  return out;
}

}  // namespace softshell::bullet
