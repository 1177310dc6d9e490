#pragma once
// The scripted headless session of softshell-demo, as a library so that tests can run it too.

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "softshell/deformation.h"
#include "softshell/hold.h"
#include "softshell/material.h"
#include "softshell/result.h"
#include "softshell/service/service.h"

namespace softshell::demo {

struct DemoOptions {
  std::filesystem::path mesh;            ///< control mesh (OBJ); empty = the shipped spot
  Material material = material_preset("rubber", 0.01).value();  ///< SI units, the mesh's unit is metres
  std::string material_name = "rubber";  ///< a preset's name gives its yield strength
  std::string server_url;                ///< empty = embedded server (with an HTTP listener for the follower)
  /// The embedded server's options (its limits, the nonlinear solver's); unused with `server_url`.
  service::ServiceOptions embedded;
  std::filesystem::path out_dir = "demo-out";
  int level = 3;                         ///< tessellation level for picking, rendering and the OBJ
  int deformations = 120;                ///< at least this many push/pull deformations (>= 10)
  /// The object's up axis (0 = x, 1 = y, 2 = z); empty = detected (the axis it rests on best,
  /// +y, the OBJ convention, when that rests as well as any).
  std::optional<int> up_axis;
  /// A brief script (two steps per phase, at most 60 Bullet steps) for tests and quick looks.
  bool short_script = false;
  /// Multiplies the loads the script chose to stay inside the linear model's range (> 1 leaves it
  /// on purpose, and the report then warns).
  double load_scale = 1.0;
  /// The model of the scripted phases (grab, push, twist, two hands): empty = each phase with the
  /// linear model while its loads stay in the linear model's range, with the nonlinear model when
  /// `load_scale` takes it out of the range (large pulls). The calibration probes are always
  /// linear (they are scaled linearly); the Bullet and shared phases stay linear.
  std::optional<DeformationModel> model;
  bool follower = true;                  ///< run the second client
  /// 2 adds the shared phase: two users' hands (each its own hold) and the Bullet bridge's holds
  /// on one object at once, followed by a third client through the event stream (1 or 2).
  int users = 1;
  bool bullet = true;                    ///< drop rigid bodies through the Bullet bridge
  int bullet_steps = 240;                ///< Bullet steps at 1/60 s
  bool pictures = true;                  ///< write PNGs
  /// With `pictures`: one large pull (the grab's point pulled by `large_pull_per_size` of the
  /// object's size, the supports held) solved with both models, drawn side by side.
  bool large_pull = true;
  double large_pull_per_size = 0.4;
  int picture_width = 800, picture_height = 600;
  std::function<void(const std::string&)> progress;  ///< progress lines (stderr), may be empty
};

/// What the session did (the summary and the --json line).
struct DemoReport {
  std::string mesh;
  std::string mesh_path;                 ///< the file read (the default: beside the installed program, else the source tree)
  std::string material;
  std::string server;                    ///< "embedded" or "remote"
  int control_points = 0, faces = 0;
  /// False if the server already held this geometry (uploaded before): nothing was precomputed
  /// and `precompute_ms` only measures the upload.
  bool precomputed_now = true;
  double precompute_ms = 0.0;
  /// How the script adapted to the object.
  struct Setup {
    char up = 'y';
    bool up_detected = true;
    double size = 0.0;                   ///< m, bounding diagonal of the rest limit surface
    double height = 0.0;                 ///< m, extent along the up axis
    int parts = 0;                       ///< connected pieces of the mesh
    int resting_parts = 0;               ///< held by the floor; the others are pinned
    int floor_points = 0;                ///< limit points held on the floor
    int pins = 0;                        ///< points pinned where they are
    std::string supports;                ///< how it is held, in words
  } setup;
  /// The loads the script chose (scaled to the material and to `load_scale`).
  struct Loads {
    double grab = 0.0;                   ///< m, largest hand displacement of the first grab
    double push = 0.0;                   ///< N, largest push
    std::vector<double> box_masses;      ///< kg
  } loads;
  int deformations = 0;                  ///< requests answered, calibration probes included
  int probes = 0;                        ///< of which calibration probes (one per phase)
  double latency_p50_ms = 0.0, latency_p95_ms = 0.0, latency_max_ms = 0.0;
  uint32_t last_res_id = 0;
  struct Follower {
    bool ran = false;
    int received = 0;
    uint32_t final_res_id = 0;
    double max_lag_ms = 0.0;
    bool matches_master = false;         ///< ends with the master's last result, same positions
  } follower;
  struct Bullet {
    bool ran = false;
    int bodies = 0;
    int on_shell = 0;                    ///< bodies resting on the shell at the end (the others fell off)
    int contacts = 0;
    int requests = 0;
    double max_deflection = 0.0;         ///< metres, limit surface
  } bullet;
  /// The shared phase (`users` = 2): holds of several clients on one object.
  struct MultiUser {
    bool ran = false;
    int users = 0;
    std::vector<int> updates;            ///< hold updates answered, per user
    double update_p50_ms = 0.0, update_p95_ms = 0.0;  ///< from HoldLease::update to the answer including it
    int solves = 0;                      ///< hold-state results stored during the phase
    int solves_measured = 0;             ///< of which seen right after their predecessor (merges counted)
    double merged_mean = 0.0;            ///< new hold versions per solve, over those measured
    int merged_max = 0;
    int bodies = 0, on_shell = 0;        ///< boxes, and those resting on the shell at the end
    int follower_received = 0;           ///< events the third client took
    double follower_lag_p50_ms = 0.0, follower_lag_max_ms = 0.0;  ///< behind the first client in this process to see a result
    uint32_t final_res_id = 0;           ///< the newest hold-state result at the end
    HoldVersions final_holds;            ///< the hold versions it includes
    bool includes_every_user = false;    ///< final_holds has each user's last version
    bool follower_matches = false;       ///< the follower ended on final_res_id, same positions
    std::string error;                   ///< why the phase could not finish ("" = it did)
  } multi_user;
  /// The final state (two hands pulling).
  struct Final {
    double max_displacement = 0.0;       ///< m, limit surface
    std::optional<double> max_von_mises; ///< Pa; empty if the server has no stresses
    double max_rotation = 0.0;           ///< rad, of the surface normal
    std::optional<double> max_strain;    ///< von Mises stress / E
    bool exceeds_yield = false;
  } final;
  /// One large pull solved with both models (`DemoOptions::large_pull`): how much each stretched
  /// the surface.
  struct LargePull {
    bool ran = false;
    double distance = 0.0;               ///< m, how far the hand pulled
    double per_size = 0.0;               ///< distance over the object's size
    double linear_area_ratio = 0.0;      ///< deformed limit surface area over the rest one
    std::optional<double> nonlinear_area_ratio;  ///< empty if the server refused the nonlinear solve
    std::string nonlinear_refused;       ///< the server's message if it did
    int nonlinear_iterations = 0;
    double linear_ms = 0.0, nonlinear_ms = 0.0;  ///< time to each answer
  } large_pull;
  /// The scripted phases solved with the nonlinear model (in script order).
  std::vector<std::string> nonlinear_phases;
  /// A result left the linear model's range: what, where and what to do (also on stderr).
  std::vector<std::string> warnings;
  /// Things worth knowing that are not wrong (stresses unavailable, geometry precomputed before).
  std::vector<std::string> notes;
  std::vector<std::string> outputs;      ///< files written
};

/// Runs the whole session. Errors (unreadable mesh, server unreachable, ...) come back as values.
Result<DemoReport> run_demo(const DemoOptions& options);

/// The human summary (stdout) and the one-line JSON object (--json).
std::string format_summary(const DemoReport& report);
std::string format_json(const DemoReport& report);

}  // namespace softshell::demo
