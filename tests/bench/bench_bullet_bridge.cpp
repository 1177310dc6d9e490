// bench_bullet_bridge: the Bullet bridge's own cost per physics step (contact gathering, force
// spreading, request building, and when a result arrives: mesh update, BVH refit, contact
// refresh) on a Horse-scale mesh (assets/meshes/catmark_righthanded.obj, 436 control points),
// for 1, 10 and 100 contact points. Target: <= 0.2 ms per step for 10 contacts.
//
// The solver is not part of this number: the session here answers every request at once with a
// precomputed displacement (so a result is applied on every step: the worst case for the mesh
// update), and stepSimulation is timed separately.

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <future>
#include <random>
#include <thread>

#include <btBulletDynamicsCommon.h>

#include "bench_support.h"
#include "softshell/bullet/shell_bridge.h"
#include "softshell/obj_io.h"
#include "test_meshes.h"

namespace softshell {
namespace {

// Answers every request immediately with the rest shape plus a displacement that changes sign
// each time (so the collision mesh really moves). Nothing is solved.
class InstantSession final : public Session {
 public:
  explicit InstantSession(const ControlMesh& mesh) : rest_(mesh.positions()) {
    Vec3 lo, hi;
    mesh.bounding_box(lo, hi);
    const double size = (hi - lo).norm();
    for (size_t i = 0; i < rest_.size(); ++i) {
      bump_.push_back(1e-3 * size * Vec3(std::sin(0.7 * double(i)), std::cos(1.3 * double(i)), std::sin(2.1 * double(i))));
    }
  }
  Result<UploadResult> upload(const ControlMesh&, const Material&, std::string_view) override {
    return UploadResult{GeomId{}, true, GeometryStatus::kReady};
  }
  std::future<Result<DeformationResult>> deform_async(const GeomId&, const DeformationRequest&) override {
    std::promise<Result<DeformationResult>> promise;
    const double sign = (next_ % 2 == 0) ? 1.0 : -1.0;
    std::vector<Vec3> positions = rest_;
    for (size_t i = 0; i < positions.size(); ++i) positions[i] += sign * bump_[i];
    promise.set_value(DeformationResult{next_++, std::move(positions)});
    return promise.get_future();
  }
  Result<std::vector<GeometryInfo>> geometries() override { return none(); }
  Result<GeometryInfo> geometry_info(const GeomId&) override { return none(); }
  Result<DeformationRequest> result_request(const GeomId&, uint32_t) override { return none(); }
  Result<Geometry> geometry(const GeomId&) override { return none(); }
  Result<DeformationResult> deform(const GeomId&, const DeformationRequest&) override { return none(); }
  Result<std::vector<uint32_t>> result_ids(const GeomId&) override { return none(); }
  Result<DeformationResult> result(const GeomId&, uint32_t) override { return none(); }
  Result<std::optional<DeformationResult>> latest_result(const GeomId&, uint32_t, std::chrono::milliseconds) override {
    return none();
  }
  Result<LimitComb> limit_comb(const GeomId&, const SurfacePoint&) override { return none(); }
  Result<StressField> stresses(const GeomId&, uint32_t, const StressQuery&) override { return none(); }

 private:
  static Error none() { return Error{ErrorCode::kInternal, "not used by the benchmark"}; }
  std::vector<Vec3> rest_, bump_;
  uint32_t next_ = 1;
};

struct Row {
  int level = 0;
  int32_t triangles = 0;
  int bodies = 0;
  double contacts = 0.0;           // mean contact points per step
  double gather_ms = 0.0;          // update() without results: gather + spread + smooth + submit
  double gather_p95 = 0.0;
  double result_ms = 0.0;          // update() applying a result every step (adds mesh update + refit)
  double result_p95 = 0.0;
  double step_ms = 0.0;            // Bullet's stepSimulation, for scale
  double applied = 0.0;            // results applied per step
};

// results: whether the session answers (every step); background: the bridge's worker thread
// prepares the collision meshes (default) or update() does it inline; real_time: one step every
// 1/120 s of wall clock (as in an app), so the worker has the time between steps.
Row run(const ControlMesh& mesh, int level, int bodies, bool results, bool background = true, bool real_time = false) {
  btDefaultCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btDiscreteDynamicsWorld world(&dispatcher, &broadphase, &solver, &configuration);
  world.setGravity(btVector3(0, 0, 0));

  auto session = std::make_shared<InstantSession>(mesh);
  bullet::ShellSettings settings;
  settings.mesh.level = level;
  settings.max_request_rate = 0.0;
  settings.min_relative_change = 0.0;  // submit every step
  settings.background_mesh_update = background;
  settings.holds.enabled = false;  // the bridge's own cost, against a test double without holds
  auto bridge = std::make_unique<bullet::ShellBridge>(world);
  const bullet::ShellId shell = bridge->add_shell(session, GeomId{}, mesh, settings).value();
  const Tessellation& t = bridge->collision_mesh(shell).tessellation();  // valid while `bridge` is
  const auto triangles = int32_t(t.triangles().size());

  // Small spheres resting on random surface points, each with its own "gravity" into the surface
  // along the normal there (so they stay put on a curved object).
  std::mt19937 rng(11);
  std::uniform_int_distribution<size_t> pick(0, t.vertices().size() - 1);
  const double size = mesh.bounding_diagonal();
  const double radius = 0.004 * size;
  btSphereShape sphere_shape(static_cast<btScalar>(radius));
  btVector3 inertia;
  sphere_shape.calculateLocalInertia(1.0f, inertia);
  std::vector<std::unique_ptr<btDefaultMotionState>> states;
  std::vector<std::unique_ptr<btRigidBody>> spheres;
  for (int b = 0; b < bodies; ++b) {
    const size_t v = pick(rng);
    const Vec3 n = t.normals()[v];
    const Vec3 at = t.vertices()[v] + n * (radius * 0.95);  // touching from the start
    btTransform start;
    start.setIdentity();
    start.setOrigin(btVector3(float(at.x()), float(at.y()), float(at.z())));
    states.push_back(std::make_unique<btDefaultMotionState>(start));
    btRigidBody::btRigidBodyConstructionInfo info(1.0f, states.back().get(), &sphere_shape, inertia);
    spheres.push_back(std::make_unique<btRigidBody>(info));
    world.addRigidBody(spheres.back().get());
    spheres.back()->setGravity(btVector3(float(-9.81 * n.x()), float(-9.81 * n.y()), float(-9.81 * n.z())));
    spheres.back()->setDamping(0.5f, 0.9f);
    spheres.back()->setActivationState(DISABLE_DEACTIVATION);
  }

  // Warm up (contacts settle, caches fill), then measure.
  const float dt = 1.0f / 120.0f;
  for (int i = 0; i < 30; ++i) {
    world.stepSimulation(dt, 1, dt);
    bridge->update();
  }
  if (!results) {
    // Keep requests unanswered from here on: a fresh bridge whose session never answers.
    bridge.reset();
    struct Silent : Session {
      std::vector<std::promise<Result<DeformationResult>>> promises;
      Result<UploadResult> upload(const ControlMesh&, const Material&, std::string_view) override {
        return Error{ErrorCode::kInternal, ""};
      }
      std::future<Result<DeformationResult>> deform_async(const GeomId&, const DeformationRequest&) override {
        promises.emplace_back();
        return promises.back().get_future();
      }
      Result<std::vector<GeometryInfo>> geometries() override { return Error{}; }
      Result<GeometryInfo> geometry_info(const GeomId&) override { return Error{}; }
      Result<DeformationRequest> result_request(const GeomId&, uint32_t) override { return Error{}; }
      Result<Geometry> geometry(const GeomId&) override { return Error{}; }
      Result<DeformationResult> deform(const GeomId&, const DeformationRequest&) override { return Error{}; }
      Result<std::vector<uint32_t>> result_ids(const GeomId&) override { return Error{}; }
      Result<DeformationResult> result(const GeomId&, uint32_t) override { return Error{}; }
      Result<std::optional<DeformationResult>> latest_result(const GeomId&, uint32_t, std::chrono::milliseconds) override {
        return Error{};
      }
      Result<LimitComb> limit_comb(const GeomId&, const SurfacePoint&) override { return Error{}; }
      Result<StressField> stresses(const GeomId&, uint32_t, const StressQuery&) override { return Error{}; }
    };
    bridge = std::make_unique<bullet::ShellBridge>(world);
    bridge->add_shell(std::make_shared<Silent>(), GeomId{}, mesh, settings).value();
    for (int i = 0; i < 5; ++i) {
      world.stepSimulation(dt, 1, dt);
      bridge->update();
    }
  }
  const int steps = 300;
  std::vector<double> update_ms, step_ms;
  double contacts = 0.0, applied = 0.0;
  auto next = bench::Clock::now();
  for (int i = 0; i < steps; ++i) {
    if (real_time) {
      next += std::chrono::microseconds(8333);
      std::this_thread::sleep_until(next);
    }
    auto t0 = bench::Clock::now();
    world.stepSimulation(dt, 1, dt);
    step_ms.push_back(bench::ms_since(t0));
    t0 = bench::Clock::now();
    const bullet::UpdateReport report = bridge->update();
    update_ms.push_back(bench::ms_since(t0));
    contacts += report.contacts;
    applied += report.results_applied;
  }
  if (std::getenv("BENCH_DEBUG") && results) {
    const auto ids = bridge->shells();
    const auto st = bridge->stats(ids.front());
    std::printf("debug: sent %s completed %s applied %s res %u err %s\n", std::to_string(st.channel.sent).c_str(),
                std::to_string(st.channel.completed).c_str(), std::to_string(st.results_applied).c_str(), st.res_id,
                st.last_error ? st.last_error->message.c_str() : "-");
  }
  bridge.reset();
  for (auto& s : spheres) world.removeRigidBody(s.get());

  Row row;
  row.level = level;
  row.triangles = triangles;
  row.bodies = bodies;
  row.contacts = contacts / steps;
  row.applied = applied / steps;
  double mean = 0.0;
  for (double x : update_ms) mean += x;
  mean /= steps;
  (results ? row.result_ms : row.gather_ms) = mean;
  (results ? row.result_p95 : row.gather_p95) = bench::percentile(update_ms, 0.95);
  double smean = 0.0;
  for (double x : step_ms) smean += x;
  row.step_ms = smean / steps;
  return row;
}

}  // namespace
}  // namespace softshell

int main(int argc, char** argv) {
  using namespace softshell;
  const std::string name = argc > 1 ? argv[1] : "catmark_righthanded.obj";
  const ControlMesh mesh = test::load_asset_mesh(name);
  std::printf("bench_bullet_bridge: %s (%d control points, %d faces), %s\n", name.c_str(), mesh.num_vertices(),
              mesh.num_faces(), bench::machine().c_str());
  std::printf("ShellBridge::update() per step; 'no result' = contacts read, spread and submitted; 'result every step' "
              "adds the collision mesh update (limit evaluation, BVH refit, shape swap, contact refresh).\n\n");
  const char* only = std::getenv("BENCH_ONLY");  // e.g. "2:10" for one row (profiling)
  std::printf("| level | triangles | bodies | contacts/step | no result | result every step, inline | result every step, background (results shown/step) | stepSimulation |\n");
  std::printf("| --- | --- | --- | --- | --- | --- | --- | --- |\n");
  for (int level : {2, 3}) {
    for (int bodies : {1, 10, 100}) {
      if (only && std::string(only) != std::to_string(level) + ":" + std::to_string(bodies)) continue;
      const Row quiet = run(mesh, level, bodies, false);
      const Row inline_update = run(mesh, level, bodies, true, false);
      const Row background = run(mesh, level, bodies, true, true, true);
      std::printf("| %d | %d | %d | %.1f | %.4f (%.4f) | %.3f (%.3f) | %.3f (%.3f) (%.2f) | %.3f |\n", level,
                  quiet.triangles, bodies, quiet.contacts, quiet.gather_ms, quiet.gather_p95, inline_update.result_ms,
                  inline_update.result_p95, background.result_ms, background.result_p95, background.applied,
                  quiet.step_ms);
    }
  }
  std::printf("\nms per ShellBridge::update(), mean (p95) over 300 steps of 1/120 s; 'inline': background_mesh_update "
              "off, steps back to back; 'background': the default, steps paced at 120 Hz wall clock.\n");
  return 0;
}
