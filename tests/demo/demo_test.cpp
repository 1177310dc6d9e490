// The demo's scripted session end to end (short): every layer working together, on every shipped
// mesh, honest about the linear model's range.
#include "demo.h"

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_STATIC
#include <stb/stb_image.h>
#include <nlohmann/json.hpp>

#include "test_meshes.h"

namespace softshell::demo {
namespace {

DemoOptions short_options(const std::string& out) {
  DemoOptions options;
  options.out_dir = std::filesystem::path(::testing::TempDir()) / out;
  std::filesystem::remove_all(options.out_dir);
  options.short_script = true;
  options.level = 2;
  options.picture_width = 160;
  options.picture_height = 120;
  return options;
}

TEST(Demo, ShortSessionRunsEveryLayer) {
  DemoOptions options = short_options("softshell-demo-test");
  options.large_pull = false;  // its nonlinear solve takes seconds on spot (LargePullIsDrawnWithBothModelsSideBySide)
  options.material = material_preset("aluminium", 0.002).value();
  options.material_name = "aluminium";
  auto report = run_demo(options);
  ASSERT_TRUE(report.ok()) << report.error().message;
  EXPECT_EQ(report->server, "embedded");
  EXPECT_TRUE(report->precomputed_now);
  EXPECT_GT(report->precompute_ms, 0.0);
  EXPECT_GE(report->deformations, 12);
  EXPECT_EQ(report->probes, 5);  // one per phase: Bullet, grab, push, twist, two hands
  EXPECT_GT(report->latency_p50_ms, 0.0);
  EXPECT_LE(report->latency_p50_ms, report->latency_max_ms);
  // spot stands on its four feet, +y up.
  EXPECT_EQ(report->setup.up, 'y');
  EXPECT_TRUE(report->setup.up_detected);
  EXPECT_EQ(report->setup.resting_parts, 1);
  EXPECT_GE(report->setup.floor_points, 3);
  EXPECT_EQ(report->setup.pins, 0);
  // The follower ends with the master's last result.
  EXPECT_TRUE(report->follower.matches_master);
  EXPECT_EQ(report->follower.final_res_id, report->last_res_id);
  EXPECT_GE(report->follower.received, 1);
  // Boxes landed on the back and dented it.
  EXPECT_GE(report->bullet.bodies, 1);
  EXPECT_EQ(report->bullet.on_shell, report->bullet.bodies);
  EXPECT_GT(report->bullet.contacts, 0);
  EXPECT_GT(report->bullet.max_deflection, 0.0);
  EXPECT_EQ(report->loads.box_masses.size(), static_cast<size_t>(report->bullet.bodies));
  // Aluminium: the loads were scaled to stay below yield and in the linear range.
  EXPECT_TRUE(report->warnings.empty()) << report->warnings.front();
  EXPECT_FALSE(report->final.exceeds_yield);
  EXPECT_GT(report->final.max_displacement, 0.0);
  EXPECT_LT(report->final.max_displacement, 0.05 * report->setup.size);
  ASSERT_TRUE(report->final.max_von_mises.has_value());
  EXPECT_GT(*report->final.max_von_mises, 0.0);
  double yield = 0.0;
  for (const auto& preset : material_presets()) {
    if (preset.name == "aluminium") yield = preset.yield_strength;
  }
  EXPECT_LE(*report->final.max_von_mises, 0.41 * yield);  // the script aims at 40% of yield at most
  for (const auto& path : report->outputs) EXPECT_TRUE(std::filesystem::exists(path)) << path;
  // Two OBJs; before, bullet, push, after, follower, stress.
  EXPECT_EQ(report->outputs.size(), 8u);

  // The --json line carries every documented field.
  const auto j = nlohmann::json::parse(format_json(*report));
  for (const char* key : {"mesh", "server", "setup", "precompute_ms", "loads", "deformations", "latency_ms", "follower",
                          "bullet", "final", "warnings", "notes", "outputs"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
  EXPECT_EQ(j["follower"]["final_res_id"].get<uint32_t>(), report->last_res_id);
  EXPECT_DOUBLE_EQ(j["final"]["max_displacement"].get<double>(), report->final.max_displacement);
  EXPECT_DOUBLE_EQ(j["final"]["max_von_mises"].get<double>(), *report->final.max_von_mises);
  EXPECT_TRUE(j["warnings"].is_array());
  EXPECT_NE(format_summary(*report).find("follower"), std::string::npos);
}

// Two users at once (--users 2): their hands, the boxes and the floor are holds of one object,
// and the third client on the event stream ends on the hold state's last result.
TEST(Demo, TwoUsersShareTheObjectAndTheFollowerEndsOnTheLastState) {
  DemoOptions options = short_options("softshell-demo-two-users");
  options.users = 2;
  options.pictures = false;
  auto report = run_demo(options);
  ASSERT_TRUE(report.ok()) << report.error().message;
  const auto& m = report->multi_user;
  ASSERT_TRUE(m.ran);
  EXPECT_EQ(m.error, "");
  EXPECT_EQ(m.users, 2);
  ASSERT_EQ(m.updates.size(), 2u);
  EXPECT_GE(m.updates[0], 2);
  EXPECT_GE(m.updates[1], 2);
  EXPECT_GT(m.update_p50_ms, 0.0);
  EXPECT_LE(m.update_p50_ms, m.update_p95_ms);
  // The follower ended on the newest hold-state result, with its positions.
  EXPECT_TRUE(m.follower_matches);
  EXPECT_GT(m.final_res_id, report->last_res_id);
  EXPECT_GE(m.follower_received, 1);
  // That result includes both users' last versions, and the bridge's floor and contacts.
  EXPECT_TRUE(m.includes_every_user);
  std::vector<std::string> ids;
  for (const auto& [id, version] : m.final_holds) {
    ids.push_back(id);
    EXPECT_GE(version, 1u) << id;
  }
  EXPECT_EQ(ids, (std::vector<std::string>{"demo.contacts", "demo.floor", "user-a.hand", "user-b.hand"}));
  // Every solve brings at least one new version (never an empty solve), and the merge counts add up.
  EXPECT_GE(m.solves, m.solves_measured);
  EXPECT_GT(m.solves_measured, 0);
  EXPECT_GE(m.merged_mean, 1.0);
  EXPECT_GE(m.merged_max, 1);
  EXPECT_EQ(m.on_shell, m.bodies);
  const auto j = nlohmann::json::parse(format_json(*report));
  EXPECT_EQ(j["multi_user"]["final_res_id"].get<uint32_t>(), m.final_res_id);
  EXPECT_EQ(j["multi_user"]["final_holds"]["user-a.hand"].get<uint64_t>(), m.final_holds[2].second);
  EXPECT_NE(format_summary(*report).find("shared (2 users)"), std::string::npos);
  // The single-user script is unchanged around it.
  EXPECT_TRUE(report->follower.matches_master);
  EXPECT_EQ(report->probes, 5);
}

// Loads past the scaled ones leave the linear range, and the report says so and what to do.
TEST(Demo, LoadsBeyondTheLinearRangeAreWarnedAbout) {
  DemoOptions options = short_options("softshell-demo-range");
  options.load_scale = 40.0;
  options.model = DeformationModel::kLinear;  // (by default these loads are solved nonlinearly)
  options.bullet = false;
  options.follower = false;
  options.pictures = false;
  auto report = run_demo(options);
  ASSERT_TRUE(report.ok()) << report.error().message;
  ASSERT_FALSE(report->warnings.empty());
  for (const auto& w : report->warnings) {
    EXPECT_NE(w.find("--load-scale"), std::string::npos) << w;
  }
  // Rubber at 40 times the aims: the strain check speaks, and names the nonlinear model.
  const auto mentions = [&](const char* text) {
    return std::any_of(report->warnings.begin(), report->warnings.end(),
                       [&](const std::string& w) { return w.find(text) != std::string::npos; });
  };
  EXPECT_TRUE(mentions("strains reach")) << report->warnings.front();
  EXPECT_TRUE(mentions("--model nonlinear"));
}

// Past the linear range (--load-scale above 2.5) the scripted phases are solved with the
// nonlinear model by default: the geometric warnings (displacement, rotation) no longer apply,
// and the material's limits are still checked, without pointing to the nonlinear model. (On the
// 32-point torus: the nonlinear model is slow on the default spot yet.)
TEST(Demo, LoadsBeyondTheLinearRangeAreSolvedWithTheNonlinearModel) {
  DemoOptions options = short_options("softshell-demo-nonlinear");
  options.mesh = test::asset_path("meshes/catmark_torus.obj");
  options.load_scale = 4.0;
  options.bullet = false;
  options.follower = false;
  options.pictures = false;
  auto report = run_demo(options);
  ASSERT_TRUE(report.ok()) << report.error().message;
  EXPECT_EQ(report->nonlinear_phases, (std::vector<std::string>{"grab", "push", "twist", "two hands"}));
  for (const auto& w : report->warnings) {
    EXPECT_EQ(w.find("--model nonlinear"), std::string::npos) << w;
    EXPECT_EQ(w.find("small displacements"), std::string::npos) << w;
    EXPECT_EQ(w.find("small rotations"), std::string::npos) << w;
  }
  EXPECT_NE(format_summary(*report).find("nonlinear model      grab, push, twist, two hands"), std::string::npos);
  EXPECT_NE(format_json(*report).find("\"nonlinear_phases\":[\"grab\""), std::string::npos);
  // Within the range nothing changes: the default run is linear.
  DemoOptions in_range = short_options("softshell-demo-in-range");
  in_range.mesh = options.mesh;
  in_range.bullet = false;
  in_range.follower = false;
  in_range.pictures = false;
  auto linear = run_demo(in_range);
  ASSERT_TRUE(linear.ok()) << linear.error().message;
  EXPECT_TRUE(linear->nonlinear_phases.empty());
}

// A PNG decoded (RGB), empty if the file is not one.
struct Png {
  int width = 0, height = 0;
  std::vector<unsigned char> rgb;
};
Png read_png(const std::filesystem::path& path) {
  Png png;
  int channels = 0;
  unsigned char* data = stbi_load(path.string().c_str(), &png.width, &png.height, &channels, 3);
  if (!data) return {};
  png.rgb.assign(data, data + static_cast<size_t>(3 * png.width * png.height));
  stbi_image_free(data);
  return png;
}

// One large pull solved with both models and drawn side by side: the linear model stretches the
// surface (a rotation is a stretch to it), the nonlinear one keeps its area closer to the rest one.
// (On the 32-point torus, held on the floor: the nonlinear solve is quick there.)
TEST(Demo, LargePullIsDrawnWithBothModelsSideBySide) {
  DemoOptions options = short_options("softshell-demo-large-pull");
  options.mesh = test::asset_path("meshes/catmark_torus.obj");
  options.bullet = false;
  options.follower = false;
  auto report = run_demo(options);
  ASSERT_TRUE(report.ok()) << report.error().message;
  const auto& p = report->large_pull;
  ASSERT_TRUE(p.ran);
  EXPECT_NEAR(p.distance, 0.4 * report->setup.size, 1e-9 * report->setup.size);
  ASSERT_TRUE(p.nonlinear_area_ratio.has_value()) << p.nonlinear_refused;
  EXPECT_GT(p.linear_area_ratio, 1.0);
  EXPECT_LT(std::abs(*p.nonlinear_area_ratio - 1.0), std::abs(p.linear_area_ratio - 1.0));
  EXPECT_GT(p.nonlinear_iterations, 0);
  // The pull is outside the latencies and the range checks; the script around it is unchanged.
  EXPECT_TRUE(report->warnings.empty()) << report->warnings.front();
  EXPECT_TRUE(report->nonlinear_phases.empty());
  EXPECT_EQ(report->probes, 4);
  const auto picture = std::find_if(report->outputs.begin(), report->outputs.end(), [](const std::string& o) {
    return std::filesystem::path(o).filename() == "large-pull-linear-vs-nonlinear.png";
  });
  ASSERT_NE(picture, report->outputs.end());
  const Png png = read_png(*picture);
  ASSERT_EQ(png.width, 2 * options.picture_width) << *picture;
  ASSERT_EQ(png.height, options.picture_height);
  // Two different answers: the panels differ in many pixels (not only in their labels).
  int differ = 0;
  for (int y = 0; y < png.height; ++y) {
    for (int x = 0; x < options.picture_width; ++x) {
      const size_t left = static_cast<size_t>(3 * (y * png.width + x)), right = left + 3 * static_cast<size_t>(options.picture_width);
      differ += std::abs(png.rgb[left] - png.rgb[right]) + std::abs(png.rgb[left + 1] - png.rgb[right + 1]) > 30;
    }
  }
  EXPECT_GT(differ, options.picture_width * options.picture_height / 50);
  const auto j = nlohmann::json::parse(format_json(*report));
  EXPECT_DOUBLE_EQ(j["large_pull"]["area_ratio"]["linear"].get<double>(), p.linear_area_ratio);
  EXPECT_DOUBLE_EQ(j["large_pull"]["area_ratio"]["nonlinear"].get<double>(), *p.nonlinear_area_ratio);
  EXPECT_NE(format_summary(*report).find("large pull"), std::string::npos);
  // Without pictures there is nothing to draw it in: no nonlinear solve.
  options.pictures = false;
  report = run_demo(options);
  ASSERT_TRUE(report.ok()) << report.error().message;
  EXPECT_FALSE(report->large_pull.ran);
  EXPECT_TRUE(nlohmann::json::parse(format_json(*report))["large_pull"]["area_ratio"]["linear"].is_null());
}

// A nonlinear solve the server refuses (here: a solver allowed one iteration) is shown as refused,
// with the server's message, beside the linear answer; never faked.
TEST(Demo, LargePullShowsARefusedNonlinearSolve) {
  DemoOptions options = short_options("softshell-demo-large-pull-refused");
  options.mesh = test::asset_path("meshes/catmark_torus.obj");
  options.bullet = false;
  options.follower = false;
  options.embedded.nonlinear.max_iterations = 1;
  auto report = run_demo(options);
  ASSERT_TRUE(report.ok()) << report.error().message;
  const auto& p = report->large_pull;
  ASSERT_TRUE(p.ran);
  EXPECT_GT(p.linear_area_ratio, 1.0);
  EXPECT_FALSE(p.nonlinear_area_ratio.has_value());
  EXPECT_NE(p.nonlinear_refused.find("iteration limit"), std::string::npos) << p.nonlinear_refused;
  EXPECT_NE(format_summary(*report).find("refused by the server: " + p.nonlinear_refused), std::string::npos);
  const auto j = nlohmann::json::parse(format_json(*report));
  EXPECT_TRUE(j["large_pull"]["area_ratio"]["nonlinear"].is_null());
  EXPECT_EQ(j["large_pull"]["nonlinear_refused"], p.nonlinear_refused);
  const Png png = read_png(std::filesystem::path(options.out_dir) / "large-pull-linear-vs-nonlinear.png");
  EXPECT_EQ(png.width, 2 * options.picture_width);
}

TEST(Demo, BadInputIsAnErrorNotACrash) {
  DemoOptions options;
  options.mesh = "/nonexistent.obj";
  auto report = run_demo(options);
  ASSERT_FALSE(report.ok());
  EXPECT_EQ(report.error().code, ErrorCode::kIoError);
  options.mesh = ::testing::TempDir();
  report = run_demo(options);
  ASSERT_FALSE(report.ok());
  EXPECT_NE(report.error().message.find("is a directory"), std::string::npos) << report.error().message;
  // A single quad: too coarse to hold and turn a point of; refused up front, saying what to do.
  const auto quad = std::filesystem::path(::testing::TempDir()) / "softshell-demo-quad.obj";
  std::ofstream(quad) << "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nf 1 4 3 2\n";
  options.mesh = quad;
  report = run_demo(options);
  ASSERT_FALSE(report.ok());
  EXPECT_EQ(report.error().code, ErrorCode::kUnprocessable);
  EXPECT_NE(report.error().message.find("subdivide it once"), std::string::npos) << report.error().message;
  options.mesh.clear();
  options.deformations = 3;
  EXPECT_EQ(run_demo(options).error().code, ErrorCode::kInvalidArgument);
  options.deformations = 120;
  options.large_pull_per_size = std::nan("");
  EXPECT_EQ(run_demo(options).error().code, ErrorCode::kInvalidArgument);
}

// --- the program itself -----------------------------------------------------------------------

struct ProgramRun {
  int status = -1;
  std::string out, err;
  nlohmann::json json;  // the last line of stdout, if it is JSON
};

// Runs softshell-demo with `args` (a shell word list), capturing both streams.
ProgramRun run_program(const std::string& args, const std::string& name) {
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / ("softshell-demo-cli-" + name);
  std::filesystem::create_directories(dir);
  const std::string command = "env -u SOFTSHELL_SERVER '" SOFTSHELL_DEMO_EXE "' " + args + " > '" + (dir / "out").string() +
                              "' 2> '" + (dir / "err").string() + "'";
  ProgramRun r;
  const int raw = std::system(command.c_str());
  r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  const auto slurp = [](const std::filesystem::path& p) {
    std::ifstream f(p);
    std::stringstream s;
    s << f.rdbuf();
    return s.str();
  };
  r.out = slurp(dir / "out");
  r.err = slurp(dir / "err");
  const auto last = r.out.rfind("\n{");
  const std::string line = r.out.substr(last == std::string::npos ? 0 : last + 1);
  if (!line.empty() && line[0] == '{') r.json = nlohmann::json::parse(line, nullptr, false);
  return r;
}

// Every shipped mesh: the script adapts to it (up axis, supports, reach, loads) and answers
// inside the linear range, or warns.
class DemoOnMesh : public ::testing::TestWithParam<std::string> {};

TEST_P(DemoOnMesh, RunsAndReportsHonestly) {
  const std::string name = GetParam();
  const std::string out = (std::filesystem::path(::testing::TempDir()) / ("softshell-demo-" + name)).string();
  const ProgramRun r = run_program("--mesh='" + test::asset_path("meshes/" + name).string() + "' --short --level=2 --no-pictures --json " +
                                "--quiet --out='" + out + "'",
                            name);
  ASSERT_EQ(r.status, 0) << r.err << r.out;
  ASSERT_TRUE(r.json.is_object()) << r.out;
  const auto& j = r.json;
  const double size = j["setup"]["size"].get<double>();
  const auto& final = j["final"];
  const double u = final["max_displacement"].get<double>();
  EXPECT_TRUE(std::isfinite(u) && u > 0.0) << u;
  EXPECT_TRUE(std::isfinite(final["max_rotation"].get<double>()));
  ASSERT_TRUE(final["max_von_mises"].is_number()) << "the embedded server has stresses";
  EXPECT_TRUE(std::isfinite(final["max_von_mises"].get<double>()));
  EXPECT_GT(final["max_von_mises"].get<double>(), 0.0);
  // Small against the object, unless a warning says otherwise (none does at the script's loads).
  EXPECT_TRUE(j["warnings"].empty()) << j["warnings"].dump();
  if (j["warnings"].empty()) {
    EXPECT_LT(u, 0.05 * size) << name;
  }
  EXPECT_TRUE(j["follower"]["matches_master"].get<bool>());
  // Held: on the floor, by pins, or fixed; never left free (the server would have refused).
  EXPECT_GT(j["setup"]["floor_points"].get<int>() + j["setup"]["pins"].get<int>() +
                (j["setup"]["supports"].get<std::string>().find("fixed") != std::string::npos),
            0);
}

INSTANTIATE_TEST_SUITE_P(ShippedMeshes, DemoOnMesh, ::testing::ValuesIn(test::asset_mesh_names()),
                         [](const ::testing::TestParamInfo<std::string>& p) { return p.param.substr(0, p.param.find('.')); });

// Up axes that a person sees at a glance: OpenSubdiv's chess pieces and tent are z-up, the torus
// and spot y-up; the car rests on its body (z), the thin hand lies flat (z).
TEST(DemoProgram, DetectsTheUpAxisAndTakesAnOverride) {
  for (const auto& [mesh, up] : {std::pair{"catmark_pawn.obj", "z"}, std::pair{"catmark_tent.obj", "z"},
                                 std::pair{"catmark_torus.obj", "y"}, std::pair{"catmark_righthanded.obj", "z"}}) {
    const ProgramRun r = run_program("--mesh '" + test::asset_path(std::string("meshes/") + mesh).string() +
                                  "' --short --level 1 --no-bullet --no-follower --no-pictures --json --quiet --out '" +
                                  ::testing::TempDir() + "/softshell-demo-up'",
                              "up");
    ASSERT_EQ(r.status, 0) << mesh << r.err;
    EXPECT_EQ(r.json["setup"]["up"], up) << mesh;
    EXPECT_TRUE(r.json["setup"]["up_detected"].get<bool>());
  }
  const ProgramRun forced = run_program("--mesh '" + test::asset_path("meshes/catmark_torus.obj").string() +
                                     "' --up=x --short --level 1 --no-bullet --no-follower --no-pictures --json --quiet --out '" +
                                     ::testing::TempDir() + "/softshell-demo-up'",
                                 "up-forced");
  ASSERT_EQ(forced.status, 0) << forced.err;
  EXPECT_EQ(forced.json["setup"]["up"], "x");
  EXPECT_FALSE(forced.json["setup"]["up_detected"].get<bool>());
}

// A softshell-server on a free port, for as long as the object lives.
class ServerProcess {
 public:
  ServerProcess() {
    int out[2];
    if (pipe(out) != 0) throw std::runtime_error("pipe failed");
    pid_ = fork();
    if (pid_ == 0) {
      dup2(out[1], 1);
      close(out[0]);
      execl(SOFTSHELL_SERVER_EXE, SOFTSHELL_SERVER_EXE, "--port=0", "--log-level=warning", static_cast<char*>(nullptr));
      _exit(127);
    }
    close(out[1]);
    std::string line;
    char c = 0;
    while (read(out[0], &c, 1) == 1 && c != '\n') line += c;
    close(out[0]);
    url_ = line.find("http://") == std::string::npos ? line : line.substr(line.find("http://"));
  }
  ~ServerProcess() {
    kill(pid_, SIGTERM);
    waitpid(pid_, nullptr, 0);
  }
  const std::string& url() const { return url_; }

 private:
  pid_t pid_ = -1;
  std::string url_;
};

// --server: the same session against a separate server. Its stresses come from the server if it
// offers them, and the report says so if it does not; the second run finds the geometry there
// already and says that nothing was precomputed.
TEST(DemoProgram, AgainstARunningServer) {
  ServerProcess server;
  ASSERT_EQ(server.url().rfind("http://127.0.0.1:", 0), 0u) << server.url();
  const std::string args = "--server " + server.url() + " --short --level 1 --no-pictures --json --quiet --out '" +
                           ::testing::TempDir() + "/softshell-demo-remote'";
  const ProgramRun first = run_program(args, "remote-1");
  ASSERT_EQ(first.status, 0) << first.err << first.out;
  EXPECT_EQ(first.json["server"], "remote");
  EXPECT_TRUE(first.json["precomputed_now"].get<bool>());
  const auto& vm = first.json["final"]["max_von_mises"];
  if (vm.is_null()) {
    EXPECT_NE(first.json["notes"].dump().find("stresses are unavailable"), std::string::npos) << first.json["notes"].dump();
  } else {
    EXPECT_TRUE(std::isfinite(vm.get<double>()));
  }
  EXPECT_TRUE(first.json["warnings"].empty()) << first.json["warnings"].dump();
  // The loads are calibrated as in-process, although positions come back in f32 (binary): small
  // probes are measured again, scaled up, instead of against rounding noise.
  const ProgramRun local = run_program("--short --level 1 --no-pictures --json --quiet --out '" + ::testing::TempDir() +
                                           "/softshell-demo-local'",
                                       "local");
  ASSERT_EQ(local.status, 0) << local.err;
  for (const char* load : {"grab", "push"}) {
    const double remote = first.json["loads"][load].get<double>(), here = local.json["loads"][load].get<double>();
    EXPECT_NEAR(remote, here, 1e-3 * std::abs(here)) << load;
  }

  const ProgramRun second = run_program(args, "remote-2");
  ASSERT_EQ(second.status, 0) << second.err;
  EXPECT_FALSE(second.json["precomputed_now"].get<bool>());
  EXPECT_TRUE(second.json["precompute_ms"].is_null());
  EXPECT_NE(second.out.find("precompute           none: the server already held this geometry"), std::string::npos)
      << second.out;
  EXPECT_EQ(second.out.find("paper Table 1"), std::string::npos);
}

// The large pull against a separate server: both answers come over HTTP (JSON: the request has a
// limit constraint and a model), the picture and the area ratios as in-process.
TEST(DemoProgram, LargePullAgainstARunningServer) {
  ServerProcess server;
  const std::string out = ::testing::TempDir() + "/softshell-demo-remote-large-pull";
  std::filesystem::remove_all(out);
  const ProgramRun r = run_program("--server " + server.url() + " --mesh '" + test::asset_path("meshes/catmark_torus.obj").string() +
                                       "' --short --level 2 --no-bullet --no-follower --json --quiet --out '" + out + "'",
                                   "remote-large-pull");
  ASSERT_EQ(r.status, 0) << r.err << r.out;
  const auto& p = r.json["large_pull"];
  ASSERT_TRUE(p["ran"].get<bool>());
  ASSERT_TRUE(p["area_ratio"]["nonlinear"].is_number()) << p.dump();
  const double linear = p["area_ratio"]["linear"].get<double>(), nonlinear = p["area_ratio"]["nonlinear"].get<double>();
  EXPECT_LT(std::abs(nonlinear - 1.0), std::abs(linear - 1.0));
  const Png png = read_png(std::filesystem::path(out) / "large-pull-linear-vs-nonlinear.png");
  EXPECT_EQ(png.width, 1600);  // two panels of the default 800 x 600
  EXPECT_EQ(png.height, 600);
  EXPECT_NE(r.json["outputs"].dump().find("large-pull-linear-vs-nonlinear.png"), std::string::npos);
}

TEST(DemoProgram, OptionsVersionAndMessages) {
  const ProgramRun version = run_program("--version", "version");
  EXPECT_EQ(version.status, 0);
  EXPECT_EQ(version.out.rfind(std::string("softshell-demo ") + SOFTSHELL_VERSION_STRING, 0), 0u) << version.out;
  const ProgramRun help = run_program("--help", "help");
  EXPECT_EQ(help.status, 0);
  for (const char* option : {"--mesh", "--material", "--thickness", "--server", "--out", "--level", "--deformations", "--up",
                             "--short", "--load-scale", "--large-pull", "--no-bullet", "--no-follower", "--no-pictures", "--quiet", "--json"}) {
    EXPECT_NE(help.out.find(option), std::string::npos) << option;
  }
  const ProgramRun bad_up = run_program("--up w", "bad-up");
  EXPECT_EQ(bad_up.status, 2);
  EXPECT_NE(bad_up.err.find("--up"), std::string::npos) << bad_up.err;
  EXPECT_EQ(run_program("--level=9", "bad-level").status, 2);
  EXPECT_EQ(run_program("--frobnicate", "unknown").status, 2);
  EXPECT_EQ(run_program("--material=unobtainium", "bad-material").status, 2);
  EXPECT_EQ(run_program("--large-pull=-0.5", "bad-large-pull").status, 2);
  const ProgramRun directory = run_program("--mesh='" + ::testing::TempDir() + "' --quiet", "directory");
  EXPECT_EQ(directory.status, 1);
  EXPECT_NE(directory.err.find("is a directory"), std::string::npos) << directory.err;
  // Nothing listens on port 1.
  const ProgramRun refused = run_program("--server=http://127.0.0.1:1 --quiet", "refused");
  EXPECT_EQ(refused.status, 1);
  EXPECT_NE(refused.err.find("connection refused: is softshell-server running at http://127.0.0.1:1?"), std::string::npos)
      << refused.err;
}

}  // namespace
}  // namespace softshell::demo
