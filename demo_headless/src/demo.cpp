// run_demo: the session from start to end, one phase after the other (each in its own file).
#include "demo.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <thread>

#include "bullet_phase.h"
#include "context.h"
#include "multi_user.h"
#include "pictures.h"
#include "script.h"
#include "softshell/embedded_session.h"
#include "softshell/obj_io.h"
#include "softshell/remote_session.h"

namespace softshell::demo {
namespace {

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

// The mesh (checked, with problems in the file's terms) and the material's yield strength.
void load(Context& c) {
  const std::filesystem::path path = c.options.mesh.empty() ? default_mesh() : c.options.mesh;
  ObjReadOptions read;
  read.validate = true;
  c.mesh = read_obj(path, read).value();
  c.options.material.check().value();
  c.report.mesh = path.filename().string();
  c.report.mesh_path = path.string();
  c.report.material = c.options.material_name;
  c.report.control_points = c.mesh.num_vertices();
  c.report.faces = c.mesh.num_faces();
  for (const MaterialPreset& preset : material_presets()) {
    if (preset.name == c.options.material_name) c.yield = preset.yield_strength;  // custom materials: unknown
  }
}

// The server: in-process with an HTTP listener for the follower, or a remote one.
void connect(Context& c) {
  if (c.options.server_url.empty()) {
    auto embedded = std::make_shared<EmbeddedSession>(c.options.embedded);
    const int port = embedded->listen("127.0.0.1", 0).value();
    c.follower_url = "http://127.0.0.1:" + std::to_string(port);
    c.session = embedded;
    c.report.server = "embedded";
    c.say("embedded server listening on " + c.follower_url + " (other clients can join)");
  } else {
    c.session = RemoteSession::connect(c.options.server_url).value();
    c.follower_url = c.options.server_url;
    c.report.server = "remote";
    c.say("connected to " + c.options.server_url);
  }
}

// Uploads and waits for the precomputation, showing its progress.
void upload(Context& c) {
  const auto start = Clock::now();
  const UploadResult uploaded = c.session->upload(c.mesh, c.options.material).value();
  c.id = uploaded.id;
  c.report.precomputed_now = uploaded.created;
  c.say("uploaded " + c.report.mesh + " as " + c.id.hex());
  for (int last_percent = -1;;) {
    const GeometryInfo info = c.session->geometry_info(c.id).value();
    if (info.status == GeometryStatus::kFailed) fail(ErrorCode::kUnprocessable, "precomputation failed: " + info.error);
    if (info.status == GeometryStatus::kReady) break;
    const int percent = static_cast<int>(100.0 * info.progress);
    if (percent / 10 != last_percent / 10) c.say("precomputing the stiffness matrix: " + std::to_string(percent) + "%");
    last_percent = percent;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  c.report.precompute_ms = ms_between(start, Clock::now());
  if (c.report.precomputed_now) {
    c.say("precomputed in " + std::to_string(static_cast<int>(c.report.precompute_ms)) + " ms");
  } else {
    c.report.notes.push_back("the server already held this geometry (uploaded before), so nothing was precomputed now");
    c.say(c.report.notes.back());
  }
}

// How the script adapts to the object.
void adapt(Context& c) {
  c.view = std::make_unique<View>(c.mesh, c.options.level);
  c.shown = c.mesh.positions();
  c.stage = adapt_to_object(c.mesh, *c.view, c.options.up_axis);
  auto& s = c.report.setup;
  s.up = c.stage.up_name();
  s.up_detected = c.stage.up_detected;
  s.size = c.stage.size;
  s.height = c.stage.height;
  s.parts = static_cast<int>(c.stage.parts.size());
  s.resting_parts = c.stage.resting_parts();
  s.floor_points = static_cast<int>(c.stage.floor_points.size());
  s.pins = static_cast<int>(c.stage.pin_points.size());
  s.supports = c.stage.describe_supports();
  c.say(std::string(1, s.up) + " up" + (s.up_detected ? " (detected)" : "") + "; " + c.stage.describe_supports());
  c.per_phase = c.options.short_script ? 2 : std::max(3, c.options.deformations / 4);
}

void finish_follower(Context& c, Follower& follower) {
  c.say("waiting for the follower to catch up with result " + std::to_string(c.report.last_res_id));
  follower.finish(c.report.last_res_id);
  auto& f = c.report.follower = follower.report();
  f.ran = true;
  f.matches_master = f.final_res_id == c.report.last_res_id && follower.positions().size() == c.shown.size();
  for (size_t i = 0; f.matches_master && i < c.shown.size(); ++i) {
    f.matches_master = (follower.positions()[i] - c.shown[i]).norm() <= 1e-6 * c.stage.size;
  }
}

// The final state: its measures, stresses and the OBJs.
std::optional<StressField> final_state(Context& c, int stress_level) {
  c.say("evaluating stresses");
  auto& f = c.report.final;
  const Response shape = measure_shape(c.view->surface, c.view->rest_vertices, c.view->rest_normals);
  f.max_displacement = shape.displacement;
  f.max_rotation = shape.rotation;
  std::optional<StressField> field = c.stresses(c.report.last_res_id, stress_level);
  if (field) {
    Response with_stresses = shape;
    add_stresses(with_stresses, *field, c.options.material);
    f.max_von_mises = with_stresses.von_mises;
    f.max_strain = with_stresses.strain;
    f.exceeds_yield = field->exceeds_yield || (c.yield > 0.0 && *f.max_von_mises > c.yield);
  }
  std::error_code ec;
  std::filesystem::create_directories(c.options.out_dir, ec);
  const auto surface_obj = c.options.out_dir / "deformed_limit_surface.obj";
  const auto cage_obj = c.options.out_dir / "deformed_control_mesh.obj";
  const Tessellation& t = c.view->surface;
  write_triangles_obj(surface_obj, t.vertices(), t.triangles(), t.normals()).value();
  ControlMesh deformed = c.mesh;
  deformed.positions() = c.shown;
  write_obj(deformed, cage_obj).value();
  c.report.outputs.push_back(surface_obj.string());
  c.report.outputs.push_back(cage_obj.string());
  return field;
}

}  // namespace

Result<DemoReport> run_demo(const DemoOptions& options) {
  return capture([&]() -> DemoReport {
    if (options.deformations < 10 && !options.short_script) {
      fail(ErrorCode::kInvalidArgument, "--deformations must be at least 10");
    }
    if (!(options.large_pull_per_size > 0.0) || !std::isfinite(options.large_pull_per_size)) {
      fail(ErrorCode::kInvalidArgument, "the large pull must be a positive fraction of the object's size");
    }
    if (options.users != 1 && options.users != 2) fail(ErrorCode::kInvalidArgument, "--users is 1 or 2");
    if (!(options.load_scale > 0.0) || !std::isfinite(options.load_scale)) {
      fail(ErrorCode::kInvalidArgument, "--load-scale must be a positive number");
    }
    DemoReport report;
    Context c(options, report);
    load(c);
    connect(c);
    upload(c);
    adapt(c);
    std::unique_ptr<Follower> follower;
    if (options.follower) follower = std::make_unique<Follower>(RemoteSession::connect(c.follower_url).value(), c.id, c.timeline);

    if (options.bullet) bullet_phase(c);
    grab_phase(c);
    push_phase(c);
    twist_phase(c);
    if (options.pictures && options.large_pull) large_pull_phase(c);  // before the held final state
    two_hands_phase(c);
    report.latency_p50_ms = percentile(c.latencies, 0.5);
    report.latency_p95_ms = percentile(c.latencies, 0.95);
    report.latency_max_ms = c.latencies.empty() ? 0.0 : *std::max_element(c.latencies.begin(), c.latencies.end());

    if (follower) finish_follower(c, *follower);
    const int stress_level = std::min(options.level, StressQuery::kMaxLevel);
    const std::optional<StressField> stresses = final_state(c, stress_level);
    report.warnings = c.range.warnings(c.stage.size, options.material, c.yield, options.material_name);
    if (options.pictures) write_pictures(c, follower.get(), stresses, stress_level);
    if (options.users == 2) multi_user_phase(c);
    return report;
  });
}

}  // namespace softshell::demo
