// The shared phase: two users' hands, the Bullet bridge's contacts and floor, all holds of one
// object, and a follower on the event stream (see multi_user.h).
#include "multi_user.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <map>
#include <mutex>
#include <numbers>
#include <thread>

#include "bullet_phase.h"
#include "follower.h"
#include "softshell/embedded_session.h"
#include "softshell/hold_lease.h"
#include "softshell/remote_session.h"

namespace softshell::demo {
namespace {

// What every client of this process saw of the hold state: each result's hold versions and when
// a client here first saw it (answers, the bridge, the follower). Thread-safe.
class Sightings {
 public:
  void saw(uint32_t res_id, const HoldVersions& holds, bool by_follower) {
    if (res_id == 0) return;
    std::lock_guard lock(mutex_);
    auto [it, fresh] = seen_.try_emplace(res_id, Seen{holds, {}, {}});
    auto& first = by_follower ? it->second.follower : it->second.others;
    if (!first) first = Clock::now();
    (void)fresh;
  }
  // New hold versions per solve, over results whose predecessor was seen too: a hold whose version
  // grew (or appeared) brings one new version per step.
  void merges(DemoReport::MultiUser& r, uint32_t after) const {
    std::lock_guard lock(mutex_);
    double sum = 0.0;
    const HoldVersions* previous = nullptr;
    uint32_t previous_id = 0;
    for (const auto& [id, seen] : seen_) {
      if (id <= after) continue;
      if (previous && id == previous_id + 1) {
        int brought = 0;
        for (const auto& [hold, version] : seen.holds) {
          // A hold new to the state brings its first version here (a re-created hold's versions
          // go on from where its last life ended, so its number says nothing).
          const uint64_t before = version_of(*previous, hold);
          brought += before == 0 ? 1 : static_cast<int>(version > before ? version - before : 0);
        }
        ++r.solves_measured;
        sum += brought;
        r.merged_max = std::max(r.merged_max, brought);
      }
      previous = &seen.holds;
      previous_id = id;
    }
    r.merged_mean = r.solves_measured ? sum / r.solves_measured : 0.0;
  }
  // The follower's lag behind the first other client here that saw each result (0 if it was first).
  std::vector<double> follower_lags() const {
    std::lock_guard lock(mutex_);
    std::vector<double> out;
    for (const auto& [id, seen] : seen_) {
      if (!seen.follower) continue;
      out.push_back(seen.others ? std::max(0.0, ms_between(*seen.others, *seen.follower)) : 0.0);
    }
    return out;
  }

 private:
  struct Seen {
    HoldVersions holds;
    std::optional<Clock::time_point> others, follower;
  };
  mutable std::mutex mutex_;
  std::map<uint32_t, Seen> seen_;
};

// One user: a hand holding a surface point and moving it along a path of its own, one update
// per 60 Hz frame, each waiting for the answer that includes it (so every update is timed).
struct User {
  std::string hold_id;
  std::unique_ptr<Session> session;
  std::unique_ptr<HoldLease> lease;
  SurfacePoint point;
  Vec3 direction;                 // of the path (unit)
  double amplitude = 0.0, phase = 0.0;
  std::vector<double> latencies;  // ms per update
  std::string error;
  std::thread thread;

  DeformationRequest at(double t) const {
    DeformationRequest r;
    const double s = amplitude * (0.5 - 0.5 * std::cos(2.0 * std::numbers::pi * t + phase));
    LimitConstraint held;
    held.point = point;
    held.displacement = s * direction;
    r.limit_constraints.push_back(held);
    return r;
  }
  void run(const std::atomic<bool>& stop, Sightings& sightings) {
    const auto start = Clock::now();
    for (int frame = 1; !stop.load(); ++frame) {
      const uint64_t before = lease->version();
      const auto sent = Clock::now();
      lease->update(at(ms_between(start, sent) / 1000.0));
      for (;;) {  // the answer that includes this update (a newer version of the hold)
        if (auto answer = lease->poll(); answer && answer->holds && version_of(*answer->holds, hold_id) > before) {
          latencies.push_back(ms_between(sent, Clock::now()));
          sightings.saw(answer->result.res_id, *answer->holds, false);
          break;
        }
        if (auto e = lease->error()) {
          error = hold_id + ": " + e->message;
          return;
        }
        if (ms_between(sent, Clock::now()) > 10000.0) {
          error = hold_id + ": no answer within 10 s";
          return;
        }
        std::this_thread::sleep_for(std::chrono::microseconds(200));
      }
      std::this_thread::sleep_until(start + frame * std::chrono::microseconds(16667));
    }
  }
};

// The third client: follows the event stream and keeps the newest result it took.
struct Follower3 {
  std::unique_ptr<Session> session;
  std::unique_ptr<EventSubscription> events;
  std::optional<HeldResult> last;
  int received = 0;
  std::string error;

  // Takes events until it holds `target` or a newer one (or 20 s pass).
  void take_until(uint32_t target, Sightings& sightings, const std::atomic<bool>* stop) {
    const auto give_up = stop ? Clock::time_point::max() : Clock::now() + std::chrono::seconds(20);
    while (Clock::now() < give_up) {
      if (stop && stop->load()) return;
      if (!stop && last && last->result.res_id >= target) return;
      auto next = events->next(std::chrono::milliseconds(50));
      if (!next) {
        error = next.error().message;
        return;
      }
      if (!*next) continue;
      if ((*next)->holds) sightings.saw((*next)->result.res_id, *(*next)->holds, true);
      last = std::move(**next);
      ++received;
    }
    if (!stop) error = "the follower did not receive result " + std::to_string(target) + " within 20 s";
  }
};

std::unique_ptr<Session> new_client(Context& c) {
  if (auto* embedded = dynamic_cast<EmbeddedSession*>(c.session.get())) {
    return std::make_unique<EmbeddedSession>(embedded->service());  // another client of the same server
  }
  return RemoteSession::connect(c.follower_url).value();
}

}  // namespace

void multi_user_phase(Context& c) {
  auto& r = c.report.multi_user;
  r.ran = true;
  r.users = 2;
  c.say("two users at once: two hands, the Bullet boxes and the floor as holds of one object; a third client follows the events");
  const auto fail_phase = [&](const std::string& why) {
    r.error = why;
    c.report.warnings.push_back("shared phase: " + why);
  };
  if (c.report.loads.grab <= 0.0) return fail_phase("no calibrated grab to scale the hands by");

  // Two points reachable from opposite sides, moved up and outwards by at most 0.3 of the
  // calibrated grab each (both together, with the boxes, stay inside the linear range's aim).
  const auto& rest = c.view->rest_vertices;
  const int32_t a = c.stage.extreme(rest, c.stage.e1, 0.3, 0.9), b = c.stage.extreme(rest, -c.stage.e1, 0.3, 0.9);
  if (a < 0 || b < 0 || a == b) return fail_phase("no two points for the hands to hold");
  Sightings sightings;
  std::vector<User> users(2);
  for (size_t k = 0; k < users.size(); ++k) {
    User& u = users[k];
    u.hold_id = k == 0 ? "user-a.hand" : "user-b.hand";
    u.session = new_client(c);
    u.point = c.view->surface.vertex_points()[static_cast<size_t>(k == 0 ? a : b)];
    u.direction = (c.stage.up + (k == 0 ? 0.5 : -0.5) * c.stage.e1).normalized();
    u.amplitude = 0.3 * c.report.loads.grab;
    u.phase = k == 0 ? 0.0 : std::numbers::pi / 2.0;
  }

  // The follower first, from the newest result on, over HTTP (the event stream).
  Follower3 follower;
  follower.session = RemoteSession::connect(c.follower_url).value();
  const std::vector<uint32_t> ids = c.session->result_ids(c.id).value();
  const uint32_t after = ids.empty() ? 0 : ids.back();
  follower.events = follower.session->subscribe(c.id, after).value();
  std::atomic<bool> stop_follower{false};
  std::atomic<bool> stop_users{false};
  std::thread follow([&] { follower.take_until(0, sightings, &stop_follower); });
  // Whatever happens below, the threads end before what they use goes away.
  struct Joiner {
    std::atomic<bool>& stop_users;
    std::atomic<bool>& stop_follower;
    std::vector<User>& users;
    std::thread& follow;
    ~Joiner() {
      stop_users = true;
      stop_follower = true;
      for (User& u : users) {
        if (u.thread.joinable()) u.thread.join();
      }
      if (follow.joinable()) follow.join();
    }
  } joiner{stop_users, stop_follower, users, follow};

  // The boxes of the Bullet phase (if it found spots), the bridge with holds "demo.floor" (the
  // supports) and "demo.contacts"; the hands start with the physics and stop before it ends.
  BulletSetup setup = bullet_setup(c);
  if (setup.spots.size() == c.report.loads.box_masses.size()) {
    setup.masses = c.report.loads.box_masses;
  } else {
    setup.spots.clear();
  }
  setup.holds_name = "demo";
  setup.step_ms = 8.333;  // twice real time: the hands' 60 Hz frames and the physics overlap
  bool started = false;
  setup.each_step = [&](uint32_t res_id, const HoldVersions& holds) {
    if (!holds.empty()) sightings.saw(res_id, holds, false);
    if (started) return;
    started = true;
    for (User& u : users) {
      HoldLeaseOptions lease;
      lease.ttl = std::chrono::seconds(5);
      u.lease = std::make_unique<HoldLease>(*u.session, c.id, u.hold_id, u.at(0.0), lease);
      u.thread = std::thread([&u, &stop_users, &sightings] { u.run(stop_users, sightings); });
    }
  };
  setup.before_release = [&] {
    stop_users = true;
    for (User& u : users) {
      if (u.thread.joinable()) u.thread.join();
    }
    // Everything is answered: the hold state's newest result, and the follower must end there.
    HoldList list = c.session->holds(c.id).value();
    for (int i = 0; i < 200 && list.state == HoldStateStatus::kSolving; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      list = c.session->holds(c.id).value();
    }
    r.final_res_id = list.res_id;
    r.solves = static_cast<int>(list.res_id - std::min(list.res_id, after));  // ids are contiguous; only holds stored meanwhile
    stop_follower = true;
    follow.join();
    follower.take_until(r.final_res_id, sightings, nullptr);
    const DeformationResult master = c.session->result(c.id, r.final_res_id).value();
    if (follower.last && follower.last->holds) r.final_holds = *follower.last->holds;
    r.follower_matches = follower.last && follower.last->result.res_id == r.final_res_id &&
                         follower.last->result.positions.size() == master.positions.size();
    for (size_t i = 0; r.follower_matches && i < master.positions.size(); ++i) {
      // As the single-user follower: a remote server's answers may come in single precision.
      r.follower_matches = (follower.last->result.positions[i] - master.positions[i]).norm() <= 1e-6 * c.stage.size;
    }
    r.includes_every_user = true;
    for (const User& u : users) {
      r.includes_every_user = r.includes_every_user && u.lease && version_of(r.final_holds, u.hold_id) == u.lease->version() &&
                              u.lease->version() > 0;
    }
    for (User& u : users) u.lease.reset();  // let go (the bridge's holds go with it)
  };
  const BulletPhaseResult world = run_bullet_world(c.session, c.id, c.mesh, setup, [](uint32_t, const std::vector<Vec3>&) {});

  std::vector<double> all;
  for (const User& u : users) {
    r.updates.push_back(static_cast<int>(u.latencies.size()));
    all.insert(all.end(), u.latencies.begin(), u.latencies.end());
    if (!u.error.empty()) fail_phase(u.error);
  }
  if (!follower.error.empty()) fail_phase("follower: " + follower.error);
  r.update_p50_ms = percentile(all, 0.5);
  r.update_p95_ms = percentile(all, 0.95);
  sightings.merges(r, after);
  const std::vector<double> lags = sightings.follower_lags();
  r.follower_received = follower.received;
  r.follower_lag_p50_ms = percentile(lags, 0.5);
  r.follower_lag_max_ms = lags.empty() ? 0.0 : *std::max_element(lags.begin(), lags.end());
  r.bodies = static_cast<int>(world.bodies.size());
  r.on_shell = static_cast<int>(std::count_if(world.bodies.begin(), world.bodies.end(), [](const auto& x) { return x.on_shell; }));
  if (!r.follower_matches) fail_phase("the follower did not end on the hold state's last result " + std::to_string(r.final_res_id));
  if (!r.includes_every_user) fail_phase("the last result does not include both users' last versions");
}

}  // namespace softshell::demo
