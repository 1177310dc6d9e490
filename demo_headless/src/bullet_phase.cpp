#include "bullet_phase.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <map>
#include <thread>

#include <btBulletDynamicsCommon.h>

#include "context.h"
#include "softshell/bullet/shell_bridge.h"

namespace softshell::demo {
namespace {

constexpr double kGravity = 9.81;

btVector3 bt(const Vec3& v) {
  return btVector3(static_cast<btScalar>(v.x()), static_cast<btScalar>(v.y()), static_cast<btScalar>(v.z()));
}

std::array<Vec3, 8> box_corners(const btTransform& pose, double half) {
  std::array<Vec3, 8> corners;
  for (int i = 0; i < 8; ++i) {
    const btVector3 c = pose * bt(half * Vec3(i & 4 ? 1 : -1, i & 2 ? 1 : -1, i & 1 ? 1 : -1));
    corners[static_cast<size_t>(i)] = Vec3(c.x(), c.y(), c.z());
  }
  return corners;
}

struct Box {
  double mass;
  std::unique_ptr<btBoxShape> shape;
  std::unique_ptr<btDefaultMotionState> motion;
  std::unique_ptr<btRigidBody> body;
};

Box make_box(const BulletSetup& setup, size_t k) {
  const auto half = static_cast<btScalar>(setup.half);
  Box b{setup.masses[k], std::make_unique<btBoxShape>(btVector3(half, half, half)), nullptr, nullptr};
  btVector3 inertia(0, 0, 0);
  b.shape->calculateLocalInertia(static_cast<btScalar>(b.mass), inertia);
  btTransform pose;
  pose.setIdentity();
  pose.setOrigin(bt(setup.spots[k] + 1.1 * setup.half * setup.up));  // just above the spot
  b.motion = std::make_unique<btDefaultMotionState>(pose);
  btRigidBody::btRigidBodyConstructionInfo info(static_cast<btScalar>(b.mass), b.motion.get(), b.shape.get(), inertia);
  info.m_friction = 0.9f;
  b.body = std::make_unique<btRigidBody>(info);
  return b;
}

// Whether Bullet holds a contact point between two objects (sleeping bodies keep their manifolds).
bool touching(btCollisionDispatcher& dispatcher, const btCollisionObject* a, const btCollisionObject* b) {
  for (int m = 0; m < dispatcher.getNumManifolds(); ++m) {
    const btPersistentManifold* manifold = dispatcher.getManifoldByIndexInternal(m);
    const bool pair = (manifold->getBody0() == a && manifold->getBody1() == b) || (manifold->getBody0() == b && manifold->getBody1() == a);
    for (int k = 0; pair && k < manifold->getNumContacts(); ++k) {
      if (manifold->getContactPoint(k).getDistance() <= 0.01f) return true;
    }
  }
  return false;
}

void debug_counters(const bullet::ShellStats& stats) {
  if (!std::getenv("SOFTSHELL_DEMO_DEBUG")) return;
  const auto count = [](auto v) { return static_cast<unsigned long long>(v); };
  std::fprintf(stderr, "bridge: submitted %llu sent %llu replaced %llu completed %llu failed %llu unchanged %llu tc %g\n",
               count(stats.channel.submitted), count(stats.channel.sent), count(stats.channel.replaced),
               count(stats.channel.completed), count(stats.channel.failed), count(stats.unchanged_frames), stats.time_constant);
  if (stats.last_error) std::fprintf(stderr, "bridge error: %s\n", stats.last_error->message.c_str());
}

// Whether a box of half edge `half` can rest on the surface at sample i: everything under its
// footprint at about that height is nearly level, something is under every quarter of it (not
// a ridge), and nothing is higher (no bump, no overhang).
class Footprints {
 public:
  Footprints(const Context& c, double half) : st_(c.stage), x_(c.view->rest_vertices), n_(c.view->rest_normals), half_(half) {
    for (size_t i = 0; i < x_.size(); ++i) cells_[cell(x_[i])].push_back(static_cast<int32_t>(i));
  }
  bool flat(int32_t i) const {
    const Vec3& p = x_[static_cast<size_t>(i)];
    const double h = st_.height_of(p);
    int quarters = 0;
    const auto [cx, cy] = cell(p);
    for (int64_t dx = -2; dx <= 2; ++dx) {
      for (int64_t dy = -2; dy <= 2; ++dy) {
        auto it = cells_.find({cx + dx, cy + dy});
        if (it == cells_.end()) continue;
        for (int32_t j : it->second) {
          const Vec3 d = x_[static_cast<size_t>(j)] - p;
          const double up = d.dot(st_.up);
          const Vec3 across = d - up * st_.up;
          if (across.norm() > 1.5 * half_ || up < -half_) continue;  // outside, or the shell's far side
          // Nearly level, nothing higher, and no dome: a box rocks on tops more curved than 4 half edges.
          if (up > 0.1 * half_ || std::abs(n_[static_cast<size_t>(j)].dot(st_.up)) < 0.94) return false;
          if (across.norm() <= half_ && up < -0.125 * half_) return false;
          if (across.norm() > 0.7 * half_) quarters |= 1 << ((across.dot(st_.e1) > 0) + 2 * (across.dot(st_.e2) > 0));
        }
      }
    }
    return quarters == 15 && h >= 0.0;
  }

 private:
  std::pair<int64_t, int64_t> cell(const Vec3& p) const {
    return {static_cast<int64_t>(std::floor(p.dot(st_.e1) / half_)), static_cast<int64_t>(std::floor(p.dot(st_.e2) / half_))};
  }
  const Stage& st_;
  const std::vector<Vec3>& x_;
  const std::vector<Vec3>& n_;
  double half_;
  std::map<std::pair<int64_t, int64_t>, std::vector<int32_t>> cells_;
};

// Up to three spots on the upper half of the main part where a box can rest, the highest first,
// each four half edges from the others. (The tops of humps hold boxes best; spots spread as far
// as possible end up on the slopes at the rim.)
std::vector<int32_t> landing_spots(const Context& c, double half) {
  const Stage& st = c.stage;
  const auto& x = c.view->rest_vertices;
  std::vector<int32_t> candidates;
  for (size_t i = 0; i < x.size(); ++i) {
    if (st.reachable[i] && std::abs(c.view->rest_normals[i].dot(st.up)) >= 0.97 && st.height_of(x[i]) >= 0.5 * st.height) {
      candidates.push_back(static_cast<int32_t>(i));
    }
  }
  std::sort(candidates.begin(), candidates.end(),
            [&](int32_t a, int32_t b) { return st.height_of(x[static_cast<size_t>(a)]) > st.height_of(x[static_cast<size_t>(b)]); });
  const Footprints footprints(c, half);
  std::vector<int32_t> spots;
  const auto apart = [&](int32_t i) {
    double d = std::numeric_limits<double>::infinity();
    for (int32_t s : spots) {
      const Vec3 v = x[static_cast<size_t>(i)] - x[static_cast<size_t>(s)];
      d = std::min(d, (v - v.dot(st.up) * st.up).norm());
    }
    return d;
  };
  for (int32_t i : candidates) {  // highest first, apart from those chosen
    if (spots.size() == 3) break;
    if (apart(i) >= 4.0 * half && footprints.flat(i)) spots.push_back(i);
  }
  return spots;
}

// A round mass (1, 2 or 5 times a power of ten) at most `kg`.
double round_mass(double kg) {
  const double decade = std::pow(10.0, std::floor(std::log10(kg)));
  for (double m : {5.0, 2.0, 1.0}) {
    if (m * decade <= kg) return m * decade;
  }
  return decade;
}

// The masses (1 : 5 : 20, the heaviest on the highest spot) from a probe of their weights.
std::vector<double> box_masses(Context& c, const std::vector<int32_t>& spots, const std::string& phase) {
  const std::vector<double> ratio = {1.0, 0.25, 0.05};
  DeformationRequest probe;
  for (size_t k = 0; k < spots.size(); ++k) {
    probe.surface_forces.push_back(
        {c.view->surface.vertex_points()[static_cast<size_t>(spots[k])], -ratio[k] * c.probe_force() * c.stage.up});
  }
  const double heaviest = round_mass(c.probe_force() * c.calibrate(probe, phase) / kGravity);
  std::vector<double> masses;
  for (size_t k = 0; k < spots.size(); ++k) masses.push_back(heaviest * ratio[k]);
  return masses;
}

}  // namespace

BulletPhaseResult run_bullet_world(const std::shared_ptr<Session>& session, const GeomId& id, const ControlMesh& mesh,
                                   const BulletSetup& setup, const OnResult& on_result) {
  BulletPhaseResult out;
  btDefaultCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btDiscreteDynamicsWorld world(&dispatcher, &broadphase, &solver, &configuration);
  world.setGravity(bt(-kGravity * setup.up));

  bullet::ShellBridge bridge(world);
  bullet::ShellSettings settings;
  settings.mesh.level = setup.level;
  // The demo steps Bullet faster than real time, so the wall-clock rate limit (made for a game
  // loop at 60 Hz) would let only a few requests through.
  settings.max_request_rate = 0.0;
  settings.supports = setup.supports;  // the bridge's floor hold
  settings.holds.name = setup.holds_name;
  const bullet::ShellId shell = bridge.add_shell(session, id, mesh, settings).value();

  // The ground under everything, so boxes that slide off still land.
  btStaticPlaneShape ground_shape(bt(setup.up), static_cast<btScalar>(setup.floor_height));
  btRigidBody ground(btRigidBody::btRigidBodyConstructionInfo(0.0f, nullptr, &ground_shape));
  world.addRigidBody(&ground);
  std::vector<Box> boxes;
  for (size_t k = 0; k < setup.spots.size(); ++k) {
    boxes.push_back(make_box(setup, k));
    world.addRigidBody(boxes.back().body.get());
  }

  // Four times real time (a 60 Hz game steps every 16.7 ms): fast enough for a demo, slow enough
  // that the server answers between frames as it would in a game.
  uint32_t shown = 0;
  const auto loop_start = std::chrono::steady_clock::now();
  for (int step = 0; step < setup.steps; ++step) {
    std::this_thread::sleep_until(loop_start + step * std::chrono::duration<double, std::milli>(setup.step_ms));
    world.stepSimulation(1.0f / 60.0f, 1, 1.0f / 60.0f);
    out.contacts += bridge.update().contacts;
    if (const uint32_t res_id = bridge.stats(shell).res_id; res_id != shown) on_result(shown = res_id, bridge.control_positions(shell));
    if (setup.each_step) setup.each_step(shown, bridge.stats(shell).shown_holds);
  }
  (void)bridge.wait_idle(std::chrono::seconds(10));
  bridge.update();
  if (setup.before_release) setup.before_release();
  const bullet::ShellStats stats = bridge.stats(shell);
  if (stats.res_id != shown) on_result(stats.res_id, bridge.control_positions(shell));
  out.requests = static_cast<int>(stats.channel.sent);
  debug_counters(stats);
  out.res_id = stats.res_id;
  if (stats.res_id != 0) out.positions = bridge.control_positions(shell);

  world.stepSimulation(1.0f / 60.0f, 1, 1.0f / 60.0f);  // contacts with the shell's newest shape
  for (const Box& b : boxes) {
    btTransform t;
    b.motion->getWorldTransform(t);
    out.bodies.push_back({box_corners(t, setup.half), b.mass, touching(dispatcher, b.body.get(), &bridge.collision_object(shell))});
    if (std::getenv("SOFTSHELL_DEMO_DEBUG")) {
      const btVector3 o = t.getOrigin();
      const Vec3 s0 = setup.spots[out.bodies.size() - 1];
      std::fprintf(stderr, "box %g kg: spot (%.3f %.3f %.3f) -> (%.3f %.3f %.3f) on shell %d\n", b.mass, s0.x(), s0.y(), s0.z(), o.x(), o.y(), o.z(),
                   int(out.bodies.back().on_shell));
    }
    world.removeRigidBody(b.body.get());
  }
  world.removeRigidBody(&ground);
  return out;
}

BulletSetup bullet_setup(const Context& c) {
  BulletSetup setup;
  setup.half = 0.03 * c.stage.size;
  for (int32_t spot : landing_spots(c, setup.half)) setup.spots.push_back(c.view->rest_vertices[static_cast<size_t>(spot)]);
  setup.supports = c.stage.supports;
  setup.up = c.stage.up;
  setup.floor_height = c.stage.floor_height;
  setup.level = std::max(1, c.options.level - 1);
  setup.steps = c.options.short_script ? std::min(c.options.bullet_steps, 60) : c.options.bullet_steps;
  return setup;
}

void bullet_phase(Context& c) {
  const std::string phase = "Bullet";
  BulletSetup setup = bullet_setup(c);
  const std::vector<int32_t> spots = landing_spots(c, setup.half);
  if (spots.empty()) {
    c.report.notes.push_back("Bullet: no flat spot on top of the object for a box to rest on; no boxes dropped");
    return;
  }
  setup.masses = box_masses(c, spots, phase);
  c.report.loads.box_masses = setup.masses;
  c.say("dropping " + std::to_string(spots.size()) + (spots.size() == 1 ? " box" : " boxes") + " on the object (Bullet)");
  auto& r = c.report.bullet;
  // Every result the bridge shows joins the range checks (the boxes land, bounce and settle),
  // measured on a level-1 tessellation so that the physics loop keeps its pace.
  Tessellation coarse = Tessellation::create(c.view->evaluator, 1).value();
  const std::vector<Vec3> coarse_rest = coarse.vertices(), coarse_normals = coarse.normals();
  const BulletPhaseResult world = run_bullet_world(c.session, c.id, c.mesh, setup, [&](uint32_t id, const std::vector<Vec3>& x) {
    c.timeline.stored(id);
    c.report.last_res_id = std::max(c.report.last_res_id, id);
    coarse.update(x);
    Response shape = measure_shape(coarse, coarse_rest, coarse_normals);
    shape.res_id = id;
    r.max_deflection = std::max(r.max_deflection, shape.displacement);
    c.range.observe(phase, shape);
  });
  r.ran = true;
  r.bodies = static_cast<int>(world.bodies.size());
  r.contacts = world.contacts;
  r.requests = world.requests;
  r.on_shell = static_cast<int>(std::count_if(world.bodies.begin(), world.bodies.end(), [](const auto& b) { return b.on_shell; }));
  if (world.positions.empty()) return;
  c.shown = world.positions;
  c.view->show(world.positions);
  Response last = measure_shape(c.view->surface, c.view->rest_vertices, c.view->rest_normals);
  last.res_id = world.res_id;
  c.range.observe(phase, last);  // the resting state at full resolution
  r.max_deflection = std::max(r.max_deflection, last.displacement);
  c.check_stresses(phase);
  Snapshot& s = c.snapshot("bullet.png", "Bullet");
  for (const auto& b : world.bodies) s.bodies.push_back({b.corners, b.mass, b.on_shell});
  c.deform(DeformationRequest{}, phase);  // the boxes are lifted off again
}

}  // namespace softshell::demo
