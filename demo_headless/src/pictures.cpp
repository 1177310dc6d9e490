#include "pictures.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>

#include "follower.h"
#include "render.h"
#include "scene.h"

namespace softshell::demo {
namespace {

constexpr Rgb kInk = {25, 25, 25};
constexpr Rgb kHand = {235, 120, 30}, kForce = {200, 30, 40}, kPin = {150, 20, 30}, kContact = {60, 60, 70};
constexpr Rgb kBoxOnShell = {225, 150, 60}, kBoxOff = {150, 150, 150};

std::string format(const char* f, double v) {
  char buf[48];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

std::string mass_text(double kg) { return kg < 1.0 ? format("%.3g g", kg * 1000.0) : format("%.3g kg", kg); }

// The factor that makes the largest displacement about 4% of the object's size, as a round
// number (1, 2 or 5 times a power of ten); 1 when it is visible as it is.
double exaggeration(double max_u, double size) {
  if (!(max_u > 0.0) || max_u >= 0.02 * size) return 1.0;
  const double f = 0.04 * size / max_u;
  const double decade = std::pow(10.0, std::floor(std::log10(f)));
  for (double m : {5.0, 2.0, 1.0}) {
    if (m * decade <= f) return std::max(1.0, m * decade);
  }
  return 1.0;
}

// The shape of a moment: the tessellation moved to it, exaggerated by `factor`, and |u| per vertex.
struct Shape {
  std::vector<double> field;
  double max_u = 0.0;
  double factor = 1.0;
  Vec3 at(const Vec3& now, const Vec3& rest) const { return rest + factor * (now - rest); }
};

Shape move_to(Tessellation& t, const std::vector<Vec3>& rest_vertices, const std::vector<Vec3>& rest_control,
              const std::vector<Vec3>& positions, double size) {
  Shape s;
  t.update(positions);
  s.field.resize(rest_vertices.size());
  for (size_t i = 0; i < rest_vertices.size(); ++i) {
    s.field[i] = (t.vertices()[i] - rest_vertices[i]).norm();
    s.max_u = std::max(s.max_u, s.field[i]);
  }
  if (s.max_u <= 1e-9 * size) {  // round-off: nothing moved
    std::fill(s.field.begin(), s.field.end(), 0.0);
    s.max_u = 0.0;
  }
  s.factor = exaggeration(s.max_u, size);
  std::vector<Vec3> shown(positions.size());
  for (size_t i = 0; i < positions.size(); ++i) shown[i] = s.at(positions[i], rest_control[i]);
  t.update(shown);
  return s;
}

struct Bounds {
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  void add(const Vec3& p) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  void add(const std::vector<Vec3>& ps) {
    for (const Vec3& p : ps) add(p);
  }
};

Camera camera_for(const Stage& st, const Bounds& b, double side) {
  return Camera::framing(b.lo, b.hi, side * (0.6 * st.e1 + 1.3 * st.e2) + 0.55 * st.up, st.up);
}

// The floor under the object (checkered), and its supports: floor contacts and pins.
void draw_ground(Renderer& r, const Stage& st, const Bounds& b) {
  const Vec3 centre = 0.5 * (b.lo + b.hi);
  const Vec3 on_floor = centre + (st.floor_height - st.up.dot(centre)) * st.up;
  const double half = 0.75 * (b.hi - b.lo - (b.hi - b.lo).dot(st.up) * st.up).cwiseAbs().maxCoeff() + 0.05 * st.size;
  // A hair below the lowest point, so the contacts are not hidden in the floor.
  const TriMesh floor = floor_tiles(on_floor - 2e-3 * st.size * st.up, st.up, half, 12);
  r.draw(floor.shaded());
}

void draw_supports(Renderer& r, const Stage& st) {
  TriMesh marks;
  for (const Vec3& p : st.floor_points) marks.append(sphere(p, 0.006 * st.size, kContact));
  for (const Vec3& p : st.pin_points) marks.append(sphere(p, 0.008 * st.size, kPin));
  r.draw(marks.shaded());
}

void draw_surface(Renderer& r, const Tessellation& t, const Shape& s) {
  ShadedMesh m{&t.vertices(), &t.normals(), &t.triangles(), &s.field, 0.0, s.max_u};
  r.draw(m);
}

void draw_ghost(Renderer& r, const View& view, double size) {
  ShadedMesh ghost{&view.rest_vertices, &view.rest_normals, &view.surface.triangles()};
  ghost.ghost = true;
  ghost.colour = {150, 175, 230};
  ghost.opacity = 0.35;
  ghost.ghost_bias = 2e-3 * size;
  r.draw(ghost);
}

void caption(Renderer& r, const std::string& title, const Shape& s, bool ghost) {
  r.paragraph(14, 14, title, kInk, 2, r.width() - 110);
  std::string note = s.factor > 1.0 ? "displacements drawn " + format("%g", s.factor) + "x" : "";
  if (ghost) note += std::string(note.empty() ? "" : "; ") + "the ghost is the rest shape";
  r.text(14, r.height() - 24, note, kInk, 1);
}

void save(Context& c, Renderer& r, const std::string& name) {
  const auto path = c.options.out_dir / name;
  r.image().write_png(path).value();
  c.report.outputs.push_back(path.string());
}

std::string bullet_caption(const Snapshot& s) {
  std::string masses;
  int on = 0;
  for (const auto& b : s.bodies) {
    masses += (masses.empty() ? "" : ", ") + mass_text(b.mass);
    on += b.on_shell;
  }
  const int n = static_cast<int>(s.bodies.size());
  if (n == 1) return "Bullet: a box of " + masses + (on ? ", resting on the shell" : ", which fell off the shell");
  const std::string where = on == n ? "all resting on the shell"
                                    : std::to_string(on) + " resting on the shell, " + std::to_string(n - on) + " fell off";
  return "Bullet: boxes of " + masses + ", " + where;
}

void draw_bodies(Renderer& r, const Snapshot& s, const Tessellation& t, const std::vector<Vec3>& rest, const Shape& shape) {
  for (const auto& b : s.bodies) {
    // A box on the shell moves with the exaggerated surface under it (its nearest vertex).
    Vec3 centre = Vec3::Zero();
    for (const Vec3& p : b.corners) centre += p / 8.0;
    size_t nearest = 0;
    for (size_t i = 0; i < rest.size(); ++i) {
      if ((rest[i] - centre).squaredNorm() < (rest[nearest] - centre).squaredNorm()) nearest = i;
    }
    const Vec3 shift = b.on_shell ? Vec3((t.vertices()[nearest] - rest[nearest]) * (1.0 - 1.0 / shape.factor)) : Vec3::Zero();
    std::array<Vec3, 8> corners = b.corners;
    for (Vec3& p : corners) p += shift;
    r.draw(box(corners, b.on_shell ? kBoxOnShell : kBoxOff).shaded());
  }
  for (const auto& b : s.bodies) {  // labels after all boxes, on those that can be seen
    Vec3 top = Vec3::Zero();
    for (const Vec3& p : b.corners) top += p / 8.0;
    const double half = 0.5 * (b.corners[7] - b.corners[0]).norm() / std::sqrt(3.0);
    if (!r.visible(top, 1.5 * half)) continue;
    if (auto px = r.project(top)) r.label((*px)[0], (*px)[1] - 22, mass_text(b.mass), kInk);
  }
}

void draw_hands_and_forces(Renderer& r, const Snapshot& s, const Shape& shape, double size) {
  TriMesh marks;
  for (const auto& h : s.hands) {
    const Vec3 point = shape.at(h.point, h.rest);
    const Vec3 hand = point + (h.position - h.point);
    marks.append(sphere(hand, 0.03 * size, kHand));
    marks.append(tube(hand, point, 0.004 * size, kHand));
    marks.append(sphere(point, 0.01 * size, kForce));
  }
  for (const auto& f : s.forces) {
    const Vec3 tip = shape.at(f.point, f.rest);
    marks.append(arrow(tip - 0.25 * size * f.force.normalized(), tip, 0.008 * size, kForce));
  }
  r.draw(marks.shaded());
  for (const auto& f : s.forces) {
    if (auto px = r.project(shape.at(f.point, f.rest) - 0.25 * size * f.force.normalized())) {
      r.label((*px)[0], (*px)[1] - 14, format("%.3g N", f.force.norm()), kInk);
    }
  }
}

// One recorded moment.
void draw_snapshot(Context& c, Tessellation& t, const Snapshot& s) {
  const Stage& st = c.stage;
  const Shape shape = move_to(t, c.view->rest_vertices, c.mesh.positions(), s.positions, st.size);
  Bounds b;
  b.add(t.vertices());
  b.add(c.view->rest_vertices);
  for (const auto& h : s.hands) b.add(shape.at(h.point, h.rest) + (h.position - h.point));
  for (const auto& f : s.forces) b.add(shape.at(f.point, f.rest) - 0.25 * st.size * f.force.normalized());
  for (const auto& body : s.bodies) {
    for (const Vec3& p : body.corners) b.add(p);
  }
  Renderer r(c.options.picture_width, c.options.picture_height, camera_for(st, b, 1.0));
  draw_ground(r, st, b);
  draw_surface(r, t, shape);
  draw_supports(r, st);
  draw_bodies(r, s, t, c.view->rest_vertices, shape);
  draw_hands_and_forces(r, s, shape, st.size);
  draw_ghost(r, *c.view, st.size);
  r.colour_bar("|u|", 0.0, shape.max_u, "m");
  caption(r, s.bodies.empty() ? s.caption : bullet_caption(s), shape, true);
  save(c, r, s.file);
}

// The large pull with both models side by side: one camera framed on both answers (and the rest
// shape), one colour scale, the rest shape as a ghost in each; a refused solve says so.
void draw_large_pull(Context& c, Tessellation& t, const LargePull& pull) {
  const Stage& st = c.stage;
  struct Panel {
    const char* name;
    const LargePull::Answer* answer;
    Shape shape;
    std::vector<Vec3> vertices, normals;
  };
  std::array<Panel, 2> panels = {Panel{"linear", &pull.linear, {}, {}, {}}, Panel{"nonlinear", &pull.nonlinear, {}, {}, {}}};
  Bounds b;
  b.add(c.view->rest_vertices);
  b.add(pull.hand.position);
  double max_u = 0.0;
  for (Panel& p : panels) {
    if (p.answer->positions.empty()) continue;
    p.shape = move_to(t, c.view->rest_vertices, c.mesh.positions(), p.answer->positions, st.size);
    p.vertices = t.vertices();
    p.normals = t.normals();
    b.add(p.vertices);
    max_u = std::max(max_u, p.shape.max_u);
  }
  const int w = c.options.picture_width, h = c.options.picture_height;
  const Camera camera = camera_for(st, b, 1.0);
  Renderer whole(2 * w, h, camera);
  for (size_t k = 0; k < panels.size(); ++k) {
    const Panel& p = panels[k];
    Renderer r(w, h, camera);
    const auto draw_hand = [&] {
      TriMesh marks;
      marks.append(sphere(pull.hand.position, 0.03 * st.size, kHand));
      marks.append(tube(pull.hand.position, pull.hand.point, 0.004 * st.size, kHand));
      marks.append(sphere(pull.hand.point, 0.01 * st.size, kForce));
      r.draw(marks.shaded());
    };
    draw_ground(r, st, b);
    int y = 14;
    if (!p.answer->positions.empty()) {
      // A large pull is drawn as it is (never exaggerated), both panels on the same scale.
      ShadedMesh m{&p.vertices, &p.normals, &t.triangles(), &p.shape.field, 0.0, max_u};
      r.draw(m);
      draw_supports(r, st);
      draw_hand();
      draw_ghost(r, *c.view, st.size);
      y = r.paragraph(14, y, p.name, kInk, 3, w - 110);
      const double change = 100.0 * (p.answer->area_ratio - 1.0);
      r.paragraph(14, y + 4, "surface area " + format("%.3g", p.answer->area_ratio) + " x rest (" +
                                 format(change >= 0.0 ? "+%.1f%%" : "%.1f%%", change) + ")",
                  kInk, 2, w - 110);
    } else {
      draw_supports(r, st);
      draw_hand();  // where the request asked the point to go
      draw_ghost(r, *c.view, st.size);
      y = r.paragraph(14, y, p.name, kInk, 3, w - 110);
      y = r.paragraph(14, y + 4, "refused by the server:", kForce, 2, w - 110);
      r.paragraph(14, y + 4, p.answer->refused, kForce, 1, w - 110);
    }
    if (k == 1) r.colour_bar("|u|", 0.0, max_u, "m");
    whole.paste(r, static_cast<int>(k) * w, 0);
  }
  whole.paragraph(14, h - 38, pull.caption + "; the same request with each model. Areas of the level-" +
                                  std::to_string(c.options.level) + " tessellation; the ghost is the rest shape",
                  kInk, 1, 2 * w - 28);
  save(c, whole, "large-pull-linear-vs-nonlinear.png");
}

void draw_before(Context& c) {
  const Stage& st = c.stage;
  Bounds b;
  b.add(c.view->rest_vertices);
  Renderer r(c.options.picture_width, c.options.picture_height, camera_for(st, b, 1.0));
  draw_ground(r, st, b);
  // Parts held fixed (too coarse to bend) in a darker blue-grey.
  std::vector<Rgb> colours(c.view->rest_vertices.size(), Rgb{190, 190, 195});
  for (size_t i = 0; i < colours.size(); ++i) {
    const int part = st.part_of_face[static_cast<size_t>(c.view->surface.vertex_points()[i].face)];
    if (st.parts[static_cast<size_t>(part)].hold == Part::Hold::kFixed) colours[i] = {120, 135, 160};
  }
  ShadedMesh rest{&c.view->rest_vertices, &c.view->rest_normals, &c.view->surface.triangles()};
  rest.colours = &colours;
  r.draw(rest);
  draw_supports(r, st);
  const int y = r.paragraph(14, 14, "before: " + c.report.mesh + " (" + std::to_string(c.report.control_points) + " control points)",
                            kInk, 2, r.width() - 28);
  r.paragraph(14, y + 4, std::string(1, st.up_name()) + " up" + (st.up_detected ? " (detected)" : "") + "; " + st.describe_supports(),
              kInk, 1, r.width() - 28);
  r.text(14, r.height() - 24,
         std::string("dark dots: floor contacts held; red: pins") + (st.fixed_parts ? "; blue-grey: parts held fixed" : ""), kInk, 1);
  save(c, r, "before.png");
}

void draw_follower(Context& c, const Follower& follower) {
  const int level = std::max(1, c.options.level - 1);
  Tessellation seen = Tessellation::create(c.view->evaluator, level).value();
  const std::vector<Vec3> seen_rest = seen.vertices();
  const Shape shape = move_to(seen, seen_rest, c.mesh.positions(), follower.positions(), c.stage.size);
  Bounds b;
  b.add(seen.vertices());
  Renderer r(c.options.picture_width, c.options.picture_height, camera_for(c.stage, b, -1.0));
  draw_ground(r, c.stage, b);
  draw_surface(r, seen, shape);
  r.colour_bar("|u|", 0.0, shape.max_u, "m");
  caption(r, "follower's view (result " + std::to_string(c.report.follower.final_res_id) + ", level " + std::to_string(level) + ")",
          shape, false);
  save(c, r, "follower.png");
}

void draw_stresses(Context& c, const StressField& field, int level) {
  Tessellation t = Tessellation::create(c.view->evaluator, level).value();
  const std::vector<Vec3> rest = t.vertices();
  const Shape shape = move_to(t, rest, c.mesh.positions(), c.shown, c.stage.size);
  std::vector<double> von_mises(field.samples.size());
  for (size_t i = 0; i < von_mises.size(); ++i) von_mises[i] = field.samples[i].von_mises();
  // Grabbed points concentrate stress; colours saturate at the 98th percentile so the rest shows.
  std::vector<double> sorted = von_mises;
  std::sort(sorted.begin(), sorted.end());
  const double max_vm = sorted.empty() ? 0.0 : sorted[static_cast<size_t>(0.98 * static_cast<double>(sorted.size() - 1))];
  const double peak = sorted.empty() ? 0.0 : sorted.back();
  Bounds b;
  b.add(t.vertices());
  Renderer r(c.options.picture_width, c.options.picture_height, camera_for(c.stage, b, 1.0));
  draw_ground(r, c.stage, b);
  r.draw({&t.vertices(), &t.normals(), &t.triangles(), &von_mises, 0.0, max_vm});
  r.colour_bar("von Mises", 0.0, max_vm, "Pa");
  const std::string yield = c.yield > 0.0 ? (field.exceeds_yield ? " (above yield!)" : " (below yield)") : "";
  caption(r, "von Mises stress, final state" + yield, shape, false);
  r.text(14, r.height() - 38, "colours saturate at the 98th percentile; the largest is " + format("%.3g Pa", peak), kInk, 1);
  save(c, r, "stress.png");
}

}  // namespace

void write_pictures(Context& c, const Follower* follower, const std::optional<StressField>& stresses, int stress_level) {
  c.say("rendering pictures");
  std::error_code ec;
  std::filesystem::create_directories(c.options.out_dir, ec);
  draw_before(c);
  Tessellation t = Tessellation::create(c.view->evaluator, c.options.level).value();
  for (const Snapshot& s : c.snapshots) draw_snapshot(c, t, s);
  if (c.large_pull) draw_large_pull(c, t, *c.large_pull);
  if (follower && !follower->positions().empty()) draw_follower(c, *follower);
  if (stresses) draw_stresses(c, *stresses, stress_level);
}

}  // namespace softshell::demo
