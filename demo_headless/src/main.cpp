// softshell-demo: a scripted push/pull session with no display (see demo.h).
#include <charconv>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>

#include "demo.h"

namespace {

constexpr const char* kUsage = R"(usage: softshell-demo [options]

Loads a Catmull-Clark control mesh, uploads it to a softshell server (in-process by default),
drops rigid bodies on it through Bullet, then plays a scripted push/pull session: rays from a
virtual hand pick points of the limit surface, grabs drag them, pushes press them, the floor holds
the object. A second client follows through latest_result. Writes OBJs and PNGs and prints a
summary.

  --mesh FILE.obj        control mesh (default: the shipped spot_control_mesh.obj); metres
  --material NAME        rubber (default), aluminium, steel, copper, titanium, glass, abs,
                         polycarbonate, wood, cardboard, silicone
  --material E,NU,T      a custom material: Young's modulus (Pa), Poisson's ratio, thickness (m)
  --thickness T          shell thickness in metres (default 0.01)
  --server URL           use a running softshell-server (e.g. http://127.0.0.1:8080)
  --out DIR              where outputs go (default: demo-out)
  --level L              tessellation level for picking, pictures and the OBJ, 1..5 (default 3)
  --deformations N       push/pull deformations, at least 10 (default 120)
  --no-bullet            skip the Bullet rigid bodies
  --no-follower          skip the second client
  --no-pictures          skip the PNGs
  --quiet                no progress on stderr
  --json                 print one JSON object as the last line of stdout
  --help                 this text

Environment: SOFTSHELL_DEMO_DEBUG=1 prints the Bullet bridge's request counters on stderr.
)";

bool parse_double(const std::string& s, double& out) {
  const char* end = s.data() + s.size();
  auto [ptr, ec] = std::from_chars(s.data(), end, out);
  return ec == std::errc() && ptr == end;
}

}  // namespace

int main(int argc, char** argv) {
  softshell::demo::DemoOptions options;
  // Default: a 1 cm rubber skin (an inflatable toy): the boxes dent it visibly and the scripted
  // grabs stay below rubber's strength, inside the linear model.
  bool quiet = false, json = false;
  double thickness = 0.01;
  std::string material_arg = "rubber";
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "softshell-demo: " << arg << " needs a value (see --help)\n";
        std::exit(2);
      }
      return argv[++i];
    };
    auto integer = [&](int lo, int hi) {
      const std::string v = value();
      int n = 0;
      auto [ptr, ec] = std::from_chars(v.data(), v.data() + v.size(), n);
      if (ec != std::errc() || ptr != v.data() + v.size() || n < lo || n > hi) {
        std::cerr << "softshell-demo: " << arg << " needs an integer in " << lo << ".." << hi << ", got '" << v << "'\n";
        std::exit(2);
      }
      return n;
    };
    if (arg == "--mesh") options.mesh = value();
    else if (arg == "--material") material_arg = value();
    else if (arg == "--thickness") {
      const std::string v = value();
      if (!parse_double(v, thickness) || !(thickness > 0.0)) {
        std::cerr << "softshell-demo: --thickness needs a positive number of metres, got '" << v << "'\n";
        return 2;
      }
    } else if (arg == "--server") options.server_url = value();
    else if (arg == "--out") options.out_dir = value();
    else if (arg == "--level") options.level = integer(1, 5);
    else if (arg == "--deformations") options.deformations = integer(10, 100000);
    else if (arg == "--no-bullet") options.bullet = false;
    else if (arg == "--no-follower") options.follower = false;
    else if (arg == "--no-pictures") options.pictures = false;
    else if (arg == "--quiet") quiet = true;
    else if (arg == "--json") json = true;
    else if (arg == "--help" || arg == "-h") {
      std::cout << kUsage;
      return 0;
    } else {
      std::cerr << "softshell-demo: unknown option '" << arg << "' (see --help)\n";
      return 2;
    }
  }

  // Material: a preset name, or "E,nu,t".
  if (material_arg.find(',') != std::string::npos) {
    std::stringstream parts(material_arg);
    std::string e, nu, t;
    std::getline(parts, e, ',');
    std::getline(parts, nu, ',');
    std::getline(parts, t, ',');
    softshell::Material m;
    if (!parse_double(e, m.youngs_modulus) || !parse_double(nu, m.poisson_ratio) || !parse_double(t, m.thickness)) {
      std::cerr << "softshell-demo: --material E,NU,T needs three numbers, e.g. 2e11,0.3,0.001\n";
      return 2;
    }
    if (auto ok = m.check(); !ok) {
      std::cerr << "softshell-demo: " << ok.error().message << "\n";
      return 2;
    }
    options.material = m;
    options.material_name = "custom (E " + e + " Pa, nu " + nu + ", t " + t + " m)";
  } else {
    auto preset = softshell::material_preset(material_arg, thickness);
    if (!preset) {
      std::cerr << "softshell-demo: " << preset.error().message << "\n";
      return 2;
    }
    options.material = *preset;
    options.material_name = material_arg;
  }
  if (!quiet) options.progress = [](const std::string& line) { std::cerr << "softshell-demo: " << line << "\n"; };

  auto report = softshell::demo::run_demo(options);
  if (!report) {
    std::cerr << "softshell-demo: " << report.error().message << "\n";
    return 1;
  }
  std::cout << softshell::demo::format_summary(*report);
  if (json) std::cout << softshell::demo::format_json(*report) << "\n";
  return report->follower.matches_master || !options.follower ? 0 : 1;
}
