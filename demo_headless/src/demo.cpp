#include "demo.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "bullet_phase.h"
#include "render.h"
#include "softshell/embedded_session.h"
#include "softshell/engine/stresses.h"
#include "softshell/interaction.h"
#include "softshell/obj_io.h"
#include "softshell/picking.h"
#include "softshell/remote_session.h"
#include "softshell/tessellation.h"

namespace softshell::demo {
namespace {

using Clock = std::chrono::steady_clock;
double ms_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p * static_cast<double>(v.size() - 1) + 0.5))];
}

// The shipped mesh: beside the installed program (<bin>/../share/softshell/assets, wherever the
// prefix was installed or moved to), else in the source tree the program was built from.
std::filesystem::path default_mesh() {
  std::vector<std::filesystem::path> dirs;
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (!ec) dirs.push_back(exe.parent_path() / SOFTSHELL_INSTALLED_ASSET_DIR_FROM_BIN);
  dirs.emplace_back(SOFTSHELL_ASSET_DIR);
  for (const auto& dir : dirs) {
    std::filesystem::path p = dir / "meshes" / "spot_control_mesh.obj";
    if (std::filesystem::exists(p, ec)) return p.lexically_normal();
  }
  return "assets/meshes/spot_control_mesh.obj";
}

// What the master client shows: the shape of the newest result, for picking and drawing. (The
// picker refers to the tessellation, so the view stays where it is constructed.)
struct View {
  View(const ControlMesh& mesh, int level)
      : evaluator(LimitEvaluator::create(mesh).value()),
        surface(Tessellation::create(evaluator, level).value()),
        picker(Picker::create(surface).value()),
        control(mesh.positions()) {}
  View(const View&) = delete;
  View& operator=(const View&) = delete;
  void show(const std::vector<Vec3>& positions) {
    control = positions;
    surface.update(positions);
    picker.refit().value();
  }
  LimitEvaluator evaluator;
  Tessellation surface;
  Picker picker;
  std::vector<Vec3> control;  // control points of the shape shown
};

// Records when the master got each result, for the follower's lag.
class Timeline {
 public:
  void stored(uint32_t res_id) {
    std::lock_guard lock(mutex_);
    at_[res_id] = Clock::now();
  }
  std::optional<Clock::time_point> when(uint32_t res_id) const {
    std::lock_guard lock(mutex_);
    auto it = at_.find(res_id);
    if (it == at_.end()) return std::nullopt;
    return it->second;
  }

 private:
  mutable std::mutex mutex_;
  std::map<uint32_t, Clock::time_point> at_;
};

// The second client (the paper's tablet): mirrors the master through latest_result.
class Follower {
 public:
  Follower(std::unique_ptr<Session> session, GeomId id, const Timeline& timeline)
      : session_(std::move(session)), id_(id), timeline_(timeline), thread_([this] { run(); }) {}
  ~Follower() { finish(0); }

  // Waits until the follower holds `last` (or gives up after a while) and stops it.
  void finish(uint32_t last) {
    {
      std::lock_guard lock(mutex_);
      target_ = last;
      stopping_ = true;
    }
    if (thread_.joinable()) thread_.join();
  }
  DemoReport::Follower report() const { return report_; }
  const std::vector<Vec3>& positions() const { return positions_; }
  const std::string& error() const { return error_; }

 private:
  void run() {
    uint32_t have = 0;
    auto give_up = Clock::time_point::max();
    while (true) {
      {
        std::lock_guard lock(mutex_);
        if (stopping_ && have >= target_) break;
        if (stopping_ && give_up == Clock::time_point::max()) give_up = Clock::now() + std::chrono::seconds(20);
      }
      if (Clock::now() > give_up) {
        error_ = "the follower did not receive result " + std::to_string(target_) + " in time";
        break;
      }
      auto answer = session_->latest_result(id_, have, std::chrono::milliseconds(500));
      if (!answer) {
        error_ = answer.error().message;
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        continue;
      }
      if (!*answer) continue;  // 204: nothing newer yet
      const auto received = Clock::now();
      const DeformationResult& result = **answer;
      have = result.res_id;
      positions_ = result.positions;
      ++report_.received;
      report_.final_res_id = have;
      if (auto stored = timeline_.when(have)) {
        report_.max_lag_ms = std::max(report_.max_lag_ms, std::max(0.0, ms_between(*stored, received)));
      }
    }
  }

  std::unique_ptr<Session> session_;
  GeomId id_;
  const Timeline& timeline_;
  std::mutex mutex_;
  uint32_t target_ = 0;
  bool stopping_ = false;
  DemoReport::Follower report_;
  std::vector<Vec3> positions_;
  std::string error_;
  std::thread thread_;  // last: starts after everything above exists
};

// Displacement magnitude of the limit surface at every tessellation vertex.
std::vector<double> displacement_field(const Tessellation& surface, const std::vector<Vec3>& rest, double& max) {
  std::vector<double> out(rest.size());
  max = 0.0;
  for (size_t i = 0; i < rest.size(); ++i) {
    out[i] = (surface.vertices()[i] - rest[i]).norm();
    max = std::max(max, out[i]);
  }
  return out;
}

}  // namespace

Result<DemoReport> run_demo(const DemoOptions& options) {
  return capture([&]() -> DemoReport {
    auto say = [&](const std::string& line) {
      if (options.progress) options.progress(line);
    };
    if (options.deformations < 10) fail(ErrorCode::kInvalidArgument, "--deformations must be at least 10");
    DemoReport report;
    const std::filesystem::path mesh_path = options.mesh.empty() ? default_mesh() : options.mesh;
    ControlMesh mesh = read_obj(mesh_path).value();
    report.mesh = mesh_path.filename().string();
    report.mesh_path = mesh_path.string();
    report.material = options.material_name;
    report.control_points = mesh.num_vertices();
    report.faces = mesh.num_faces();
    options.material.check().value();

    // The server: in-process with an HTTP listener for the follower, or a remote one.
    std::shared_ptr<Session> master;
    std::string follower_url = options.server_url;
    if (options.server_url.empty()) {
      auto embedded = std::make_shared<EmbeddedSession>();
      const int port = embedded->listen("127.0.0.1", 0).value();
      follower_url = "http://127.0.0.1:" + std::to_string(port);
      master = embedded;
      report.server = "embedded";
      say("embedded server listening on " + follower_url + " (other clients can join)");
    } else {
      master = RemoteSession::connect(options.server_url).value();
      report.server = "remote";
      say("connected to " + options.server_url);
    }

    // Upload and wait for the precomputation, showing its progress.
    const auto upload_start = Clock::now();
    const UploadResult uploaded = master->upload(mesh, options.material).value();
    const GeomId id = uploaded.id;
    say("uploaded " + report.mesh + " as " + id.hex());
    for (int last_percent = -1;;) {
      const GeometryInfo info = master->geometry_info(id).value();
      if (info.status == GeometryStatus::kFailed) fail(ErrorCode::kUnprocessable, "precomputation failed: " + info.error);
      if (info.status == GeometryStatus::kReady) break;
      const int percent = static_cast<int>(100.0 * info.progress);
      if (percent / 10 != last_percent / 10) say("precomputing the stiffness matrix: " + std::to_string(percent) + "%");
      last_percent = percent;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    report.precompute_ms = ms_between(upload_start, Clock::now());
    say("precomputed in " + std::to_string(static_cast<int>(report.precompute_ms)) + " ms");

    // What the master shows and picks on.
    View view(mesh, options.level);
    const std::vector<Vec3> rest_vertices = view.surface.vertices();
    Vec3 lo, hi;
    mesh.bounding_box(lo, hi);
    const Vec3 centre = 0.5 * (lo + hi);
    const double size = (hi - lo).norm();

    // The floor under the object (+y up, as in OBJ files), holding whatever touches it.
    double floor_y = std::numeric_limits<double>::infinity();
    for (const Vec3& p : rest_vertices) floor_y = std::min(floor_y, p.y());
    FloorContact floor;
    for (double tolerance : {0.01, 0.03, 0.06, 0.12}) {
      floor = floor_contact(view.surface, Plane{Vec3(0.0, floor_y, 0.0), Vec3::UnitY()}, {tolerance * size}).value();
      if (floor.fixes_rigid_motion) break;
    }
    if (!floor.fixes_rigid_motion) {
      fail(ErrorCode::kUnprocessable, "the object does not rest stably on the floor below it (its lowest points lie on a line)");
    }
    say("floor: " + std::to_string(floor.points.size()) + " contact points hold the object");

    Timeline timeline;
    std::unique_ptr<Follower> follower;
    if (options.follower) {
      follower = std::make_unique<Follower>(RemoteSession::connect(follower_url).value(), id, timeline);
    }

    // Bullet first: rigid bodies dent the resting object through the bridge.
    if (options.bullet) {
      say("dropping rigid bodies on the object (Bullet)");
      BulletPhaseResult bullet = run_bullet_phase(master, id, mesh, floor, floor_y, view.picker, options.level, options.bullet_steps,
                                                  [&](uint32_t res_id) { timeline.stored(res_id); });
      report.bullet.bodies = bullet.bodies;
      report.bullet.contacts = bullet.contacts;
      report.bullet.requests = bullet.requests;
      if (!bullet.positions.empty()) {
        view.show(bullet.positions);
        double max = 0.0;
        const auto field = displacement_field(view.surface, rest_vertices, max);
        report.bullet.max_deflection = max;
        if (options.pictures) {
        Renderer r(options.picture_width, options.picture_height,
                   Camera::framing(lo, hi, Vec3(0.9, 0.8, 1.3), Vec3::UnitY()));
        r.draw({&view.surface.vertices(), &view.surface.normals(), &view.surface.triangles(), &field, 0.0, max});
        for (const auto& body : bullet.body_meshes) r.draw({&body.vertices, &body.normals, &body.triangles, nullptr, 0, 1});
        r.colour_bar("dent |u|", 0.0, max, "m");
        r.text(14, 14, "Bullet: boxes of 1, 5 and 20 kg resting on the shell", {25, 25, 25}, 2);
        std::error_code ec;
        std::filesystem::create_directories(options.out_dir, ec);
        const auto path = options.out_dir / "bullet.png";
        r.image().write_png(path).value();
        report.outputs.push_back(path.string());
        }
      }
      view.show(mesh.positions());
    }

    // The push/pull script: rays from a virtual hand pick points of the limit surface; grabs drag
    // them, pushes press them; the floor holds the object all along.
    std::vector<double> latencies;
    std::vector<Vec3> last_positions = mesh.positions();
    auto deform = [&](const DeformationRequest& extra) {
      DeformationRequest request = extra;
      floor.add_to(request);
      const auto start = Clock::now();
      DeformationResult result = master->deform(id, request).value();
      latencies.push_back(ms_between(start, Clock::now()));
      timeline.stored(result.res_id);
      report.last_res_id = std::max(report.last_res_id, result.res_id);
      last_positions = result.positions;
      view.show(result.positions);
      ++report.deformations;
      return result;
    };
    // Aims the hand's ray at `target`; if it misses (the object is not where a generic script
    // expects it), sweeps towards the centre of the bounding box until it hits.
    auto pick_towards = [&](const Vec3& hand, const Vec3& target) {
      for (double s : {1.0, 0.75, 0.5, 0.25, 0.0}) {
        const Vec3 aim = centre + s * (target - centre);
        auto pick = view.picker.pick(Ray{hand, (aim - hand).normalized()}).value();
        if (pick) return *pick;
      }
      fail(ErrorCode::kInvalidArgument, "the scripted hand's rays miss this object; is it empty around its centre?");
    };
    const int per_phase = std::max(3, options.deformations / 4);
    const Vec3 up = Vec3::UnitY();

    say("grab: pulling a point of the back up and out");
    {
      Pose hand{centre + Vec3(0.1 * size, 1.2 * size, 0.2 * size), Eigen::Quaterniond::Identity()};
      const Pick pick = pick_towards(hand.position, centre + Vec3(0.1 * size, 0.0, 0.0));
      const Grab grab = Grab::begin(view.evaluator, pick.point, view.control, hand).value();
      const Vec3 start = hand.position;
      for (int k = 1; k <= per_phase; ++k) {
        hand.position = start + (double(k) / per_phase) * (0.04 * size * up + 0.02 * size * Vec3::UnitZ());
        DeformationRequest r;
        r.limit_constraints.push_back(grab.constraint(hand));
        deform(r);
      }
      deform(DeformationRequest{});  // release: the object springs back
    }

    say("push: pressing the side with a growing force");
    {
      const Vec3 hand = centre + Vec3(0.0, 0.05 * size, 1.3 * size);
      const Pick pick = pick_towards(hand, centre + Vec3(0.0, 0.05 * size, 0.0));
      // Calibrate: the response to 1 N, then forces up to a dent of 2% of the object's size.
      DeformationRequest unit;
      unit.surface_forces.push_back(push(pick, (centre - hand).normalized(), 1.0));
      deform(unit);
      double unit_dent = 0.0;
      for (size_t i = 0; i < last_positions.size(); ++i) {
        unit_dent = std::max(unit_dent, (last_positions[i] - mesh.positions()[i]).norm());
      }
      const double full = unit_dent > 0.0 ? 0.02 * size / unit_dent : 1.0;
      for (int k = 1; k < per_phase; ++k) {
        DeformationRequest r;
        r.surface_forces.push_back(push(pick, (centre - hand).normalized(), full * k / (per_phase - 1)));
        deform(r);
      }
    }

    say("grab with the tangent plane: twisting a point while lifting it");
    {
      Pose hand{centre + Vec3(-0.9 * size, 0.4 * size, 0.3 * size), Eigen::Quaterniond::Identity()};
      const Pick pick = pick_towards(hand.position, centre + Vec3(-0.2 * size, 0.2 * size, 0.0));
      const Grab grab = Grab::begin(view.evaluator, pick.point, view.control, hand, {true, true}).value();
      const Vec3 start = hand.position;
      for (int k = 1; k <= per_phase; ++k) {
        const double s = double(k) / per_phase;
        hand.position = start + s * 0.04 * size * up;
        hand.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(0.15 * s, (pick.position - start).normalized()));
        DeformationRequest r;
        r.limit_constraints.push_back(grab.constraint(hand));
        deform(r);
      }
    }

    say("two hands: pulling two points apart (held at the end)");
    {
      Pose left{centre + Vec3(-1.2 * size, 0.3 * size, 0.0), Eigen::Quaterniond::Identity()};
      Pose right{centre + Vec3(1.2 * size, 0.3 * size, 0.0), Eigen::Quaterniond::Identity()};
      const Pick a = pick_towards(left.position, centre + Vec3(0.0, 0.15 * size, 0.0));
      const Pick b = pick_towards(right.position, centre + Vec3(0.0, 0.15 * size, 0.0));
      const Grab ga = Grab::begin(view.evaluator, a.point, view.control, left).value();
      const Grab gb = Grab::begin(view.evaluator, b.point, view.control, right).value();
      const Vec3 l0 = left.position, r0 = right.position;
      const int steps = std::max(per_phase, options.deformations - report.deformations);
      for (int k = 1; k <= steps; ++k) {
        const double s = double(k) / steps;
        left.position = l0 - s * 0.02 * size * Vec3::UnitX() + s * 0.01 * size * up;
        right.position = r0 + s * 0.02 * size * Vec3::UnitX() + s * 0.01 * size * up;
        DeformationRequest r;
        r.limit_constraints.push_back(ga.constraint(left));
        r.limit_constraints.push_back(gb.constraint(right));
        deform(r);
      }
    }
    report.latency_p50_ms = percentile(latencies, 0.5);
    report.latency_p95_ms = percentile(latencies, 0.95);
    report.latency_max_ms = latencies.empty() ? 0.0 : *std::max_element(latencies.begin(), latencies.end());

    // The follower must end with the master's last result.
    if (follower) {
      say("waiting for the follower to catch up with result " + std::to_string(report.last_res_id));
      follower->finish(report.last_res_id);
      report.follower = follower->report();
      report.follower.matches_master = report.follower.final_res_id == report.last_res_id &&
                                       follower->positions().size() == last_positions.size();
      for (size_t i = 0; report.follower.matches_master && i < last_positions.size(); ++i) {
        report.follower.matches_master = (follower->positions()[i] - last_positions[i]).norm() <= 1e-6 * size;
      }
    }

    // Stresses of the final state (the engine, locally, on the same mesh and material).
    say("evaluating stresses");
    auto model = engine::ShellModel::build(mesh, options.material).value();
    Eigen::VectorXd u(3 * mesh.num_vertices());
    for (int32_t i = 0; i < mesh.num_vertices(); ++i) {
      u.segment<3>(3 * i) = last_positions[static_cast<size_t>(i)] - mesh.positions()[static_cast<size_t>(i)];
    }
    double yield = std::numeric_limits<double>::infinity();  // custom materials: no yield check
    for (const MaterialPreset& preset : material_presets()) {
      if (preset.name == options.material_name) yield = preset.yield_strength;
    }
    const engine::StressSummary stress = engine::max_stress(*model, u, yield);
    report.max_von_mises = stress.max.von_mises();
    report.exceeds_yield = stress.exceeds_yield;

    // Outputs.
    std::error_code ec;
    std::filesystem::create_directories(options.out_dir, ec);
    const auto surface_obj = options.out_dir / "deformed_limit_surface.obj";
    const auto cage_obj = options.out_dir / "deformed_control_mesh.obj";
    write_triangles_obj(surface_obj, view.surface.vertices(), view.surface.triangles(), view.surface.normals()).value();
    ControlMesh deformed = mesh;
    deformed.positions() = last_positions;
    write_obj(deformed, cage_obj).value();
    report.outputs.push_back(surface_obj.string());
    report.outputs.push_back(cage_obj.string());
    double max_u = 0.0;
    const std::vector<double> field = displacement_field(view.surface, rest_vertices, max_u);
    report.max_displacement = max_u;

    if (options.pictures) {
      say("rendering pictures");
      const Camera camera = Camera::framing(lo, hi, Vec3(0.9, 0.5, 1.4), Vec3::UnitY());
      auto save = [&](Renderer& r, const std::string& name) {
        const auto path = options.out_dir / name;
        r.image().write_png(path).value();
        report.outputs.push_back(path.string());
      };
      {
        Tessellation rest = Tessellation::create(view.evaluator, options.level).value();
        Renderer r(options.picture_width, options.picture_height, camera);
        r.draw({&rest.vertices(), &rest.normals(), &rest.triangles(), nullptr, 0.0, 1.0});
        r.text(14, 14, "before: " + report.mesh + " (" + std::to_string(report.control_points) + " control points)",
               {25, 25, 25}, 2);
        save(r, "before.png");
      }
      {
        Renderer r(options.picture_width, options.picture_height, camera);
        r.draw({&view.surface.vertices(), &view.surface.normals(), &view.surface.triangles(), &field, 0.0, max_u});
        r.colour_bar("|u|", 0.0, max_u, "m");
        r.text(14, 14, "after: two hands pulling, floor holding", {25, 25, 25}, 2);
        save(r, "after.png");
      }
      if (follower && !follower->positions().empty()) {
        Tessellation seen = Tessellation::create(view.evaluator, std::max(1, options.level - 1)).value();
        const std::vector<Vec3> seen_rest = seen.vertices();
        seen.update(follower->positions());
        double max_seen = 0.0;
        const auto seen_field = displacement_field(seen, seen_rest, max_seen);
        Renderer r(options.picture_width, options.picture_height, Camera::framing(lo, hi, Vec3(-1.3, 0.7, -0.6), Vec3::UnitY()));
        r.draw({&seen.vertices(), &seen.normals(), &seen.triangles(), &seen_field, 0.0, max_seen});
        r.colour_bar("|u|", 0.0, max_seen, "m");
        r.text(14, 14, "follower's view (result " + std::to_string(report.follower.final_res_id) + ", level " +
                           std::to_string(std::max(1, options.level - 1)) + ")",
               {25, 25, 25}, 2);
        save(r, "follower.png");
      }
      {
        std::vector<double> von_mises(view.surface.vertex_points().size());
        double max_vm = 0.0;
        for (size_t i = 0; i < von_mises.size(); ++i) {
          von_mises[i] = engine::evaluate_stress(*model, u, view.surface.vertex_points()[i]).von_mises();
          max_vm = std::max(max_vm, von_mises[i]);
        }
        Renderer r(options.picture_width, options.picture_height, camera);
        r.draw({&view.surface.vertices(), &view.surface.normals(), &view.surface.triangles(), &von_mises, 0.0, max_vm});
        r.colour_bar("von Mises", 0.0, max_vm, "Pa");
        r.text(14, 14, std::string("von Mises stress") + (report.exceeds_yield ? " (above yield: outside the linear model)" : ""),
               {25, 25, 25}, 2);
        save(r, "stress.png");
      }
    }
    return report;
  });
}

std::string format_summary(const DemoReport& r) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(2);
  s << "softshell-demo: " << r.mesh << " (" << r.control_points << " control points, " << r.faces << " faces), "
    << r.material << ", " << r.server << " server\n"
    << "  precompute           " << r.precompute_ms << " ms   (paper Table 1: 7-82 s for 210-472 control points)\n"
    << "  deformations         " << r.deformations << " (grab, push, tangent grab, two hands; floor held)\n"
    << "  latency per request  p50 " << r.latency_p50_ms << " ms, p95 " << r.latency_p95_ms << " ms, max "
    << r.latency_max_ms << " ms   (paper: 2-75 ms solve, 1-5 frames = up to 83 ms end to end)\n"
    << "  follower             received " << r.follower.received << ", final result " << r.follower.final_res_id
    << (r.follower.matches_master ? " = master's last" : " (DIFFERS from the master's last)") << ", max lag "
    << r.follower.max_lag_ms << " ms\n"
    << "  Bullet               " << r.bullet.bodies << " bodies, " << r.bullet.contacts << " contact points, "
    << r.bullet.requests << " requests, max dent " << r.bullet.max_deflection * 1000.0 << " mm\n"
    << "  final state          max |u| " << r.max_displacement * 1000.0 << " mm, max von Mises "
    << r.max_von_mises / 1e6 << " MPa" << (r.exceeds_yield ? " (above yield!)" : " (below yield)") << "\n";
  s << "  outputs             ";
  for (const auto& o : r.outputs) s << " " << o;
  s << "\n";
  return s.str();
}

std::string format_json(const DemoReport& r) {
  nlohmann::json j = {
      {"mesh", r.mesh},
      {"mesh_path", r.mesh_path},
      {"server", r.server},
      {"deformations", r.deformations},
      {"precompute_ms", r.precompute_ms},
      {"latency_ms", {{"p50", r.latency_p50_ms}, {"p95", r.latency_p95_ms}, {"max", r.latency_max_ms}}},
      {"follower", {{"received", r.follower.received}, {"final_res_id", r.follower.final_res_id}, {"max_lag_ms", r.follower.max_lag_ms}}},
      {"bullet", {{"bodies", r.bullet.bodies}, {"contacts", r.bullet.contacts}, {"max_deflection", r.bullet.max_deflection}}},
      {"outputs", r.outputs},
  };
  return j.dump();
}

}  // namespace softshell::demo
