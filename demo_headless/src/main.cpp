// softshell-demo: a scripted push/pull session with no display (see demo.h).
#include <charconv>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>

// GCC 12 sees a "potential null pointer dereference" inside CLI11's string splitting (a false
// positive of its middle end, inlined into this file); the header is not ours to change.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wnull-dereference"
#include <CLI/CLI.hpp>
#pragma GCC diagnostic pop

#include "demo.h"
#include "softshell/malloc_tuning.h"

namespace {

constexpr const char* kDescription =
    "Loads a Catmull-Clark control mesh, uploads it to a softshell server (in-process by default),\n"
    "drops boxes on it through Bullet, then plays a scripted push/pull session: rays from a virtual\n"
    "hand pick points of the limit surface, grabs drag them, pushes press them. The script adapts to\n"
    "the object: its size, its up axis, how it rests (on the floor, or pinned where it cannot rest),\n"
    "where a hand can reach it, and loads scaled to the material so that every result stays inside\n"
    "the linear model's range (a warning says when one does not). A second client follows through\n"
    "latest_result. One large pull is solved with both models, linear and nonlinear, and drawn side\n"
    "by side. Writes OBJs and PNGs and prints a summary.\n\n"
    "Options take their value as --opt value or --opt=value.\n";

constexpr const char* kFooter =
    "Environment: SOFTSHELL_SERVER is --server's default; SOFTSHELL_DEMO_DEBUG=1 prints on stderr\n"
    "how the script adapted (rest analysis, pins, reach, probes, boxes) and the Bullet bridge's\n"
    "request counters.\n";

struct Args {
  softshell::demo::DemoOptions demo;
  std::string material = "rubber";
  double thickness = 0.01;  // a 1 cm rubber skin (an inflatable toy)
  std::string up;
  std::string model;  // empty: chosen per phase
  double large_pull = 0.4;  // of the object's size; 0 = none
  bool quiet = false, json = false, no_bullet = false, no_follower = false, no_pictures = false;
};

void add_options(CLI::App& app, Args& a) {
  app.add_option("--mesh", a.demo.mesh, "control mesh (default: the shipped spot_control_mesh.obj); metres")
      ->type_name("FILE.obj");
  app.add_option("--material", a.material,
                 "rubber (default), aluminium, steel, copper, titanium, glass, abs,\n"
                 "polycarbonate, wood, cardboard, silicone; or E,NU,T: a custom material's\n"
                 "Young's modulus (Pa), Poisson's ratio and thickness (m)")
      ->type_name("NAME|E,NU,T");
  app.add_option("--thickness", a.thickness, "shell thickness of a preset in metres (default 0.01)")
      ->type_name("T")->check(CLI::PositiveNumber.description(""));
  app.add_option("--server", a.demo.server_url, "use a running softshell-server (e.g. http://127.0.0.1:8080)")
      ->type_name("URL")->envname("SOFTSHELL_SERVER");
  app.add_option("--out", a.demo.out_dir, "where outputs go (default: demo-out)")->type_name("DIR");
  app.add_option("--level", a.demo.level, "tessellation level for picking, pictures and the OBJ, 1..5 (default 3)")
      ->type_name("L")->check(CLI::Range(1, 5).description(""));
  app.add_option("--deformations", a.demo.deformations, "push/pull deformations, at least 10 (default 120)")
      ->type_name("N")->check(CLI::Range(10, 100000).description(""));
  app.add_option("--up", a.up, "the object's up axis (default: detected; +y, the OBJ convention, unless\nthe object rests better on another axis)")
      ->type_name("x|y|z")->check(CLI::IsMember({"x", "y", "z"}).description(""));
  app.add_flag("--short", a.demo.short_script, "a brief script: two steps per phase, at most 60 Bullet steps");
  app.add_option("--load-scale", a.demo.load_scale,
                 "multiplies the loads the script chose to stay inside the linear range\n(default 1; above about 2 the results leave it, and the demo warns)")
      ->type_name("F")->check(CLI::PositiveNumber.description(""));
  app.add_option("--model", a.model,
                 "the scripted phases' model: linear or nonlinear (default: linear while the\nloads stay in its range, nonlinear past it, e.g. --load-scale 4)")
      ->type_name("linear|nonlinear")->check(CLI::IsMember({"linear", "nonlinear"}).description(""));
  app.add_option("--users", a.demo.users,
                 "2 adds a shared phase: two users' hands (each its own hold) and the Bullet\nboxes on one object at once, a third client following the events (default 1)")
      ->type_name("N")->check(CLI::Range(1, 2).description(""));
  app.add_flag("--no-bullet", a.no_bullet, "skip the Bullet boxes");
  app.add_flag("--no-follower", a.no_follower, "skip the second client");
  app.add_flag("--no-pictures", a.no_pictures, "skip the PNGs");
  app.add_option("--large-pull", a.large_pull,
                 "with pictures: one large pull, the hand moved by F times the object's size,\nsolved with both models and drawn side by side (default 0.4; 0 skips it)")
      ->type_name("F")->check(CLI::NonNegativeNumber.description(""));
  app.add_flag("--quiet", a.quiet, "no progress on stderr (warnings still go there)");
  app.add_flag("--json", a.json, "print one JSON object as the last line of stdout");
}

bool parse_double(const std::string& s, double& out) {
  const char* end = s.data() + s.size();
  auto [ptr, ec] = std::from_chars(s.data(), end, out);
  return ec == std::errc() && ptr == end;
}

// A preset name, or "E,nu,t".
softshell::Result<void> set_material(Args& a) {
  if (a.material.find(',') == std::string::npos) {
    auto preset = softshell::material_preset(a.material, a.thickness);
    if (!preset) return preset.error();
    a.demo.material = *preset;
    a.demo.material_name = a.material;
    return {};
  }
  std::stringstream parts(a.material);
  std::string e, nu, t, extra;
  std::getline(parts, e, ',');
  std::getline(parts, nu, ',');
  std::getline(parts, t, ',');
  softshell::Material m;
  if (!parse_double(e, m.youngs_modulus) || !parse_double(nu, m.poisson_ratio) || !parse_double(t, m.thickness) ||
      std::getline(parts, extra, ',')) {
    return softshell::Error{softshell::ErrorCode::kInvalidArgument,
                            "--material E,NU,T needs three numbers, e.g. 2e11,0.3,0.001"};
  }
  if (auto ok = m.check(); !ok) return ok.error();
  a.demo.material = m;
  a.demo.material_name = "custom (E " + e + " Pa, nu " + nu + ", t " + t + " m)";
  return {};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app(kDescription, "softshell-demo");
  app.footer(kFooter);
  app.set_version_flag("--version", std::string("softshell-demo ") + SOFTSHELL_VERSION_STRING, "print the version and exit");
  app.get_formatter()->column_width(30);
  Args a;
  add_options(app, a);
  try {
    app.parse(argc, argv);
  } catch (const CLI::Success& e) {  // --help, --version
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "softshell-demo: " << e.what() << "\n(see softshell-demo --help)\n";
    return 2;
  }
  softshell::tune_malloc_for_solves();  // as softshell-server does (softshell/malloc_tuning.h)
  if (auto ok = set_material(a); !ok) {
    std::cerr << "softshell-demo: " << ok.error().message << "\n";
    return 2;
  }
  if (!a.up.empty()) a.demo.up_axis = a.up[0] - 'x';
  if (!a.model.empty()) {
    a.demo.model = a.model == "nonlinear" ? softshell::DeformationModel::kNonlinear : softshell::DeformationModel::kLinear;
  }
  a.demo.bullet = !a.no_bullet;
  a.demo.follower = !a.no_follower;
  a.demo.pictures = !a.no_pictures;
  a.demo.large_pull = a.large_pull > 0.0;
  if (a.demo.large_pull) a.demo.large_pull_per_size = a.large_pull;
  if (!a.quiet) a.demo.progress = [](const std::string& line) { std::cerr << "softshell-demo: " << line << "\n"; };

  auto report = softshell::demo::run_demo(a.demo);
  if (!report) {
    std::cerr << "softshell-demo: " << report.error().message << "\n";
    return 1;
  }
  for (const auto& w : report->warnings) std::cerr << "softshell-demo: warning: " << w << "\n";
  std::cout << softshell::demo::format_summary(*report);
  if (a.json) std::cout << softshell::demo::format_json(*report) << "\n";
  const bool shared_ok = !report->multi_user.ran || report->multi_user.error.empty();
  return (report->follower.matches_master || !a.demo.follower) && shared_ok ? 0 : 1;
}
