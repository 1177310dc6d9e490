#pragma once
// What every phase of the demo's script shares: the session, the object and how it is held, what
// the master shows, and the record of what happened (for the follower's lag, the latencies, the
// linear-range checks and the pictures).

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "demo.h"
#include "follower.h"
#include "linear_range.h"
#include "softshell/session.h"
#include "stage.h"

namespace softshell::demo {

/// One moment of the session, for a picture.
struct Snapshot {
  std::string file;                    ///< e.g. "push.png"
  std::string caption;
  std::vector<Vec3> positions;         ///< control points shown
  struct Hand {
    Vec3 position;                     ///< where the hand is
    Vec3 point, rest;                  ///< the point it holds, where it is now and at rest
  };
  std::vector<Hand> hands;
  struct Force {
    Vec3 point, rest;                  ///< where it acts, now and at rest
    Vec3 force;                        ///< N
  };
  std::vector<Force> forces;
  struct Body {
    std::array<Vec3, 8> corners;       ///< a box where it came to rest
    double mass = 0.0;                 ///< kg
    bool on_shell = false;
  };
  std::vector<Body> bodies;
};

/// One large pull solved with both models (the same request), for the side-by-side picture.
struct LargePull {
  Snapshot::Hand hand;                 ///< the hand where it pulls to, and the point it holds
  double distance = 0.0;               ///< m, how far the hand moved
  std::string caption;                 ///< what was pulled, where to
  struct Answer {
    std::vector<Vec3> positions;       ///< control points (empty: refused)
    std::string refused;               ///< the server's message when it refused the request
    double area_ratio = 0.0;           ///< limit surface area over the rest one (level-N tessellation)
    int iterations = 0;                ///< Newton iterations (nonlinear)
    double ms = 0.0;                   ///< time to the answer
  } linear, nonlinear;
};

struct Context {
  Context(const DemoOptions& o, DemoReport& r) : options(o), report(r) {}

  const DemoOptions& options;
  DemoReport& report;
  std::shared_ptr<Session> session;
  std::string follower_url;            ///< where a second client connects
  GeomId id;
  ControlMesh mesh;
  double yield = 0.0;                  ///< Pa, of the material preset (0 = unknown)
  std::unique_ptr<View> view;
  Stage stage;
  Timeline timeline;
  RangeMonitor range;
  std::vector<double> latencies;       ///< ms per request
  std::vector<Vec3> shown;             ///< control points of the newest result
  std::vector<Snapshot> snapshots;
  std::optional<LargePull> large_pull;  ///< the side-by-side comparison, if it ran
  int per_phase = 0;                   ///< steps of each scripted phase
  /// The model `deform` solves with (set per phase by `calibrate`; probes are linear).
  DeformationModel model = DeformationModel::kLinear;

  void say(const std::string& line) const;
  /// Solves `extra` together with the supports with the model `with`, and shows the result; the
  /// server's error if it refuses. Records it for the follower but not in the latencies or the
  /// range checks (see `deform`).
  Result<DeformationResult> solve(const DeformationRequest& extra, DeformationModel with);
  /// Solves `extra` together with the supports, shows the result and records it under `phase`.
  DeformationResult deform(const DeformationRequest& extra, const std::string& phase);
  /// A probe for `phase`: solves it, measures it (stresses included, if the server has them) and
  /// returns the factor that brings it to the linear range's aims, times `options.load_scale`.
  /// (Leaves `model` linear.)
  double calibrate(const DeformationRequest& probe, const std::string& phase);
  /// Sets `model` for a scripted phase: `options.model`, or by default the nonlinear model when
  /// `load_scale` takes the phase's loads out of the linear range; records a nonlinear phase.
  void choose_model(const std::string& phase);
  /// Stresses of a phase's worst result join the range checks.
  void check_stresses(const std::string& phase);
  /// Stresses of a result, if the server has them (if not, says so once in the notes).
  std::optional<StressField> stresses(uint32_t res_id, int level);
  /// A small displacement for probes (m): a thousandth of the thickness or of the aim.
  double probe_length() const;
  /// A force for probes (N) that moves the object by less than `probe_length`: the stiffness of a
  /// plate as wide as the object (E t^3 / size^2) is below that of any part of it.
  double probe_force() const;
  /// Adds a snapshot of the shape shown now.
  Snapshot& snapshot(const std::string& file, const std::string& caption);

 private:
  bool stresses_unavailable_ = false;
};

}  // namespace softshell::demo
