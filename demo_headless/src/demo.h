#pragma once
// The scripted headless session of softshell-demo, as a library so that tests can run it too.

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "softshell/material.h"
#include "softshell/result.h"

namespace softshell::demo {

struct DemoOptions {
  std::filesystem::path mesh;            ///< control mesh (OBJ); empty = the shipped spot
  Material material = material_preset("rubber", 0.01).value();  ///< SI units, the mesh's unit is metres
  std::string material_name = "rubber";
  std::string server_url;                ///< empty = embedded server (with an HTTP listener for the follower)
  std::filesystem::path out_dir = "demo-out";
  int level = 3;                         ///< tessellation level for picking, rendering and the OBJ
  int deformations = 120;                ///< at least this many push/pull deformations (>= 10)
  bool follower = true;                  ///< run the second client
  bool bullet = true;                    ///< drop rigid bodies through the Bullet bridge
  int bullet_steps = 240;                ///< Bullet steps at 1/60 s
  bool pictures = true;                  ///< write PNGs
  int picture_width = 800, picture_height = 600;
  std::function<void(const std::string&)> progress;  ///< progress lines (stderr), may be empty
};

/// What the session did (the summary and the --json line).
struct DemoReport {
  std::string mesh;
  std::string mesh_path;  // the file read (the default: beside the installed program, else the source tree)
  std::string material;
  std::string server;                    ///< "embedded" or "remote"
  int control_points = 0, faces = 0;
  int deformations = 0;
  double precompute_ms = 0.0;
  double latency_p50_ms = 0.0, latency_p95_ms = 0.0, latency_max_ms = 0.0;
  uint32_t last_res_id = 0;
  struct Follower {
    int received = 0;
    uint32_t final_res_id = 0;
    double max_lag_ms = 0.0;
    bool matches_master = false;         ///< ends with the master's last result, same positions
  } follower;
  struct Bullet {
    int bodies = 0;
    int contacts = 0;
    int requests = 0;
    double max_deflection = 0.0;         ///< metres, limit surface
  } bullet;
  double max_displacement = 0.0;         ///< metres, final push/pull state (limit surface)
  double max_von_mises = 0.0;            ///< Pa, final push/pull state
  bool exceeds_yield = false;
  std::vector<std::string> outputs;      ///< files written
};

/// Runs the whole session. Errors (unreadable mesh, server unreachable, ...) come back as values.
Result<DemoReport> run_demo(const DemoOptions& options);

/// The human summary (stdout) and the one-line JSON object (--json).
std::string format_summary(const DemoReport& report);
std::string format_json(const DemoReport& report);

}  // namespace softshell::demo
