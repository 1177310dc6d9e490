#include "script.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <tuple>

#include "softshell/interaction.h"

namespace softshell::demo {
namespace {

// A hand near a point of the object, and the point its ray picks.
struct Reach {
  Vec3 hand;
  Pick pick;
};

// Puts a hand at 0.15 sizes from the rest sample `sample`, coming from `approach` (or along the
// surface normal if something else is in the way), and casts its ray at the sample.
Reach reach(const Context& c, int32_t sample, const Vec3& approach, const char* what) {
  if (sample < 0) fail(ErrorCode::kInternal, std::string("no point of the object for the ") + what);
  const View& view = *c.view;
  const Vec3 target = view.surface.vertices()[static_cast<size_t>(sample)];
  Vec3 normal = view.surface.normals()[static_cast<size_t>(sample)];
  if (normal.dot(approach) < 0.0) normal = -normal;
  const double distance = 0.15 * c.stage.size;
  // A ray at a vertex on an open boundary can pass just outside it: then aim into a triangle there.
  std::vector<Vec3> aims = {target};
  for (const auto& tri : view.surface.triangles()) {
    if (tri[0] == sample || tri[1] == sample || tri[2] == sample) {
      const auto& v = view.surface.vertices();
      aims.push_back((v[static_cast<size_t>(tri[0])] + v[static_cast<size_t>(tri[1])] + v[static_cast<size_t>(tri[2])]) / 3.0);
      break;
    }
  }
  std::optional<Reach> first;
  for (const Vec3& aim : aims) {
    for (const Vec3& from : {Vec3(approach.normalized()), normal}) {
      const Vec3 hand = target + distance * from;
      auto pick = view.picker.pick(Ray{hand, aim - hand}).value();
      if (!pick) continue;
      if ((pick->position - target).norm() <= 0.02 * c.stage.size) return {hand, *pick};
      if (!first) first = Reach{hand, *pick};
    }
  }
  if (std::getenv("SOFTSHELL_DEMO_DEBUG")) {
    std::fprintf(stderr, "reach %s: sample %d at (%.3f %.3f %.3f) face %d, picked %s\n", what, sample, target.x(), target.y(),
                 target.z(), view.surface.vertex_points()[static_cast<size_t>(sample)].face, first ? "something else" : "nothing");
  }
  if (first) return *first;  // something in front of the point: the hand takes that
  fail(ErrorCode::kInternal, std::string("the scripted hand's ray misses the object (") + what + ")");
}

const std::vector<Vec3>& rest(const Context& c) { return c.view->rest_vertices; }

// Back to the rest shape: nothing but the supports.
void let_go(Context& c, const std::string& phase) { c.deform(DeformationRequest{}, phase); }

std::string length(double metres) {
  char buf[32];
  std::snprintf(buf, sizeof buf, metres < 0.1 ? "%.3g mm" : "%.3g m", metres < 0.1 ? metres * 1000.0 : metres);
  return buf;
}

std::string mm(double metres) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g mm", metres * 1000.0);
  return buf;
}

}  // namespace

void grab_phase(Context& c) {
  const std::string phase = "grab";
  const Vec3 pull = (c.stage.up + 0.5 * c.stage.e2).normalized();
  const Reach r = reach(c, c.stage.extreme(rest(c), c.stage.up, 0.0, 1.0), c.stage.up, "grab");
  Pose hand{r.hand, Eigen::Quaterniond::Identity()};
  const Grab grab = Grab::begin(c.view->evaluator, r.pick.point, c.view->control, hand).value();
  const auto at = [&](double d) {
    DeformationRequest request;
    request.limit_constraints.push_back(grab.constraint(Pose{r.hand + d * pull, hand.orientation}));
    return request;
  };
  const double probe = c.probe_length();
  const double full = probe * c.calibrate(at(probe), phase);
  c.choose_model(phase);
  c.report.loads.grab = full;
  c.say("grab: pulling the top up and out by up to " + mm(full));
  for (int k = 1; k <= c.per_phase; ++k) c.deform(at(full * k / c.per_phase), phase);
  c.check_stresses(phase);
  let_go(c, phase);  // the object springs back
}

void push_phase(Context& c) {
  const std::string phase = "push";
  const Reach r = reach(c, c.stage.extreme(rest(c), c.stage.e2, 0.3, 0.7), c.stage.e2, "push");
  const Vec3 direction = (r.pick.position - r.hand).normalized();
  const auto with = [&](double newtons) {
    DeformationRequest request;
    request.surface_forces.push_back(push(r.pick, direction, newtons));
    return request;
  };
  const double probe = c.probe_force();
  const double full = probe * c.calibrate(with(probe), phase);
  c.choose_model(phase);
  c.report.loads.push = full;
  char force[32];
  std::snprintf(force, sizeof force, "%.3g N", full);
  c.say(std::string("push: pressing the side with up to ") + force);
  for (int k = 1; k <= c.per_phase; ++k) {
    const DeformationResult result = c.deform(with(full * k / c.per_phase), phase);
    if (k < c.per_phase) continue;
    Snapshot& s = c.snapshot("push.png", std::string("push: ") + force + " on the side");
    s.forces.push_back({c.view->evaluator.evaluate(r.pick.point, result.positions).position,
                        c.view->evaluator.evaluate(r.pick.point).position, full * direction});
  }
  c.check_stresses(phase);
  let_go(c, phase);
}

void twist_phase(Context& c) {
  const std::string phase = "twist";
  const Reach r = reach(c, c.stage.extreme(rest(c), -c.stage.e2, 0.4, 0.9), -c.stage.e2, "twist");
  const Grab grab = Grab::begin(c.view->evaluator, r.pick.point, c.view->control, Pose{r.hand, Eigen::Quaterniond::Identity()}, {true, true}).value();
  // The hand turns about its ray, so the point stays on the axis and only its tangent plane turns.
  const Vec3 axis = (r.pick.position - r.hand).normalized();
  const double turn_per_length = 1.0 / (0.05 * c.stage.size);  // rad per m of lift
  const auto at = [&](double lift) {
    const Pose hand{r.hand + lift * c.stage.up, Eigen::Quaterniond(Eigen::AngleAxisd(lift * turn_per_length, axis))};
    DeformationRequest request;
    request.limit_constraints.push_back(grab.constraint(hand));
    return request;
  };
  const double probe = c.probe_length();
  const double full = probe * c.calibrate(at(probe), phase);
  c.choose_model(phase);
  char line[128];
  std::snprintf(line, sizeof line, "twist: lifting a point by up to %s while turning its tangent plane by %.2g degrees",
                mm(full).c_str(), full * turn_per_length * 180.0 / 3.14159265358979);
  c.say(line);
  for (int k = 1; k <= c.per_phase; ++k) c.deform(at(full * k / c.per_phase), phase);
  c.check_stresses(phase);
  let_go(c, phase);
}

void large_pull_phase(Context& c) {
  const std::string phase = "large pull";
  // The grab phase's point and direction, pulled as far as a hand in VR pulls.
  const Vec3 pull = (c.stage.up + 0.5 * c.stage.e2).normalized();
  const Reach r = reach(c, c.stage.extreme(rest(c), c.stage.up, 0.0, 1.0), c.stage.up, "large pull");
  const Pose from{r.hand, Eigen::Quaterniond::Identity()};
  const Grab grab = Grab::begin(c.view->evaluator, r.pick.point, c.view->control, from).value();
  LargePull out;
  out.distance = c.options.large_pull_per_size * c.stage.size;
  const Pose to{r.hand + out.distance * pull, from.orientation};
  out.hand = {to.position, grab.target(to), grab.rest_position()};
  char line[160];
  std::snprintf(line, sizeof line, "the top pulled %s (%.0f%% of the object's size) up and out, the supports held",
                length(out.distance).c_str(), 100.0 * c.options.large_pull_per_size);
  out.caption = line;
  c.say("large pull: " + out.caption + ", with both models");
  DeformationRequest request;
  request.limit_constraints.push_back(grab.constraint(to));
  const auto& triangles = c.view->surface.triangles();
  const double rest_area = surface_area(c.view->rest_vertices, triangles);
  const auto solve = [&](DeformationModel model, LargePull::Answer& a) {
    const auto start = Clock::now();
    auto result = c.solve(request, model);
    a.ms = ms_between(start, Clock::now());
    // A nonlinear solve that cannot reach equilibrium is a 422 that says why: shown as such.
    if (!result && (model == DeformationModel::kLinear || result.error().code != ErrorCode::kUnprocessable)) {
      throw Exception(result.error());
    }
    if (!result) {
      a.refused = result.error().message;
      return;
    }
    a.positions = result->positions;
    a.iterations = result->iterations;
    a.area_ratio = surface_area(c.view->surface.vertices(), triangles) / rest_area;
  };
  solve(DeformationModel::kLinear, out.linear);
  solve(DeformationModel::kNonlinear, out.nonlinear);
  auto& rep = c.report.large_pull;
  rep.ran = true;
  rep.distance = out.distance;
  rep.per_size = c.options.large_pull_per_size;
  rep.linear_area_ratio = out.linear.area_ratio;
  rep.linear_ms = out.linear.ms;
  rep.nonlinear_ms = out.nonlinear.ms;
  if (out.nonlinear.refused.empty()) {
    rep.nonlinear_area_ratio = out.nonlinear.area_ratio;
    rep.nonlinear_iterations = out.nonlinear.iterations;
    std::snprintf(line, sizeof line, "large pull: surface area %.3g times the rest area (linear), %.3g (nonlinear, %d iterations)",
                  out.linear.area_ratio, out.nonlinear.area_ratio, out.nonlinear.iterations);
    c.say(line);
  } else {
    rep.nonlinear_refused = out.nonlinear.refused;
    c.say("large pull: the server refused the nonlinear solve: " + out.nonlinear.refused);
  }
  c.large_pull = std::move(out);
  let_go(c, phase);
}

void two_hands_phase(Context& c) {
  const std::string phase = "two hands";
  const Reach left = reach(c, c.stage.extreme(rest(c), -c.stage.e1, 0.3, 0.7), -c.stage.e1, "left hand");
  const Reach right = reach(c, c.stage.extreme(rest(c), c.stage.e1, 0.3, 0.7), c.stage.e1, "right hand");
  const Grab a = Grab::begin(c.view->evaluator, left.pick.point, c.view->control, Pose{left.hand, Eigen::Quaterniond::Identity()}).value();
  const Grab b = Grab::begin(c.view->evaluator, right.pick.point, c.view->control, Pose{right.hand, Eigen::Quaterniond::Identity()}).value();
  const Vec3 out_left = (-c.stage.e1 + 0.5 * c.stage.up).normalized(), out_right = (c.stage.e1 + 0.5 * c.stage.up).normalized();
  const auto at = [&](double d) {
    DeformationRequest request;
    request.limit_constraints.push_back(a.constraint(Pose{left.hand + d * out_left, Eigen::Quaterniond::Identity()}));
    request.limit_constraints.push_back(b.constraint(Pose{right.hand + d * out_right, Eigen::Quaterniond::Identity()}));
    return request;
  };
  const double probe = c.probe_length();
  const double full = probe * c.calibrate(at(probe), phase);
  c.choose_model(phase);
  c.say("two hands: pulling two points apart by up to " + mm(full) + " each (held at the end)");
  const int steps = c.options.short_script ? c.per_phase : std::max(c.per_phase, c.options.deformations - c.report.deformations);
  for (int k = 1; k <= steps; ++k) c.deform(at(full * k / steps), phase);
  Snapshot& s = c.snapshot("after.png", "after: two hands pulling apart by " + mm(full) + " each");
  for (const auto& [hand, grab, out] : {std::tuple{left.hand, &a, out_left}, std::tuple{right.hand, &b, out_right}}) {
    const Vec3 now = hand + full * out;
    s.hands.push_back({now, grab->target(Pose{now, Eigen::Quaterniond::Identity()}), grab->rest_position()});
  }
  c.check_stresses(phase);
}

}  // namespace softshell::demo
