#include "stage.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <numeric>

#include "softshell/interaction.h"

namespace softshell::demo {
namespace {

// Samples this close to the floor (of the object's size) touch it: the smallest of these at which
// the object rests (a model need not stand exactly level on its lowest points).
constexpr double kContactTolerances[] = {0.005, 0.01, 0.02, 0.04};
// A part rests if its centroid lies this far (of its size) inside the hull of its contacts.
constexpr double kMinMargin = 0.01;
// Hands keep this distance (of the part's size) from the supports.
constexpr double kReachClearance = 0.1;

using Vec2 = Eigen::Vector2d;

// Connected pieces of the mesh (faces sharing a control point), numbered 0.. in face order.
std::vector<int32_t> parts_of_faces(const ControlMesh& mesh, int& count) {
  std::vector<int32_t> root(static_cast<size_t>(mesh.num_vertices()));
  std::iota(root.begin(), root.end(), 0);
  const auto find = [&](int32_t v) {
    while (root[static_cast<size_t>(v)] != v) v = root[static_cast<size_t>(v)] = root[static_cast<size_t>(root[static_cast<size_t>(v)])];
    return v;
  };
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    const auto face = mesh.face(f);
    for (int32_t v : face) root[static_cast<size_t>(find(v))] = find(face[0]);
  }
  std::vector<int32_t> number(root.size(), -1), out(static_cast<size_t>(mesh.num_faces()));
  count = 0;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    int32_t& n = number[static_cast<size_t>(find(mesh.face(f)[0]))];
    if (n < 0) n = count++;
    out[static_cast<size_t>(f)] = n;
  }
  return out;
}

// Convex hull (counter-clockwise, no collinear points), Andrew's monotone chain.
std::vector<Vec2> convex_hull(std::vector<Vec2> p) {
  std::sort(p.begin(), p.end(), [](const Vec2& a, const Vec2& b) { return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y()); });
  if (p.size() < 3) return p;
  const auto cross = [](const Vec2& o, const Vec2& a, const Vec2& b) {
    return (a - o).x() * (b - o).y() - (a - o).y() * (b - o).x();
  };
  std::vector<Vec2> h(2 * p.size());
  size_t k = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  for (size_t i = p.size() - 1, t = k + 1; i > 0; --i) {
    while (k >= t && cross(h[k - 2], h[k - 1], p[i - 1]) <= 0) --k;
    h[k++] = p[i - 1];
  }
  h.resize(k - 1);
  return h;
}

// How far `c` lies inside the convex polygon `hull` (negative: outside or degenerate).
double inside_margin(const std::vector<Vec2>& hull, const Vec2& c) {
  if (hull.size() < 3) return -1.0;
  double margin = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < hull.size(); ++i) {
    const Vec2 a = hull[i], b = hull[(i + 1) % hull.size()];
    const Vec2 edge = b - a;
    const double d = (edge.x() * (c - a).y() - edge.y() * (c - a).x()) / edge.norm();  // > 0 on the inner side
    margin = std::min(margin, d);
  }
  return margin;
}

Vec3 axis_vector(int axis) { return Vec3::Unit(axis); }

// The floor under the object along `axis`, and which parts rest on it: those whose centroid
// lies inside the hull of their surface samples that touch the floor (and the same for the
// whole object, which tells the up axis).
struct Resting {
  double tolerance = 0.0;   // length unit
  double floor_height = 0.0;
  FloorContact contact;
  std::vector<char> rests;  // per part
  double margin = 0.0;      // of the whole object (of its size): how stably it rests, all parts together
};

Resting rest_on(const View& view, const std::vector<int32_t>& part_of_face, const std::vector<Part>& parts, int axis,
                double size, double tolerance) {
  Resting r;
  r.tolerance = tolerance;
  const Vec3 up = axis_vector(axis);
  r.floor_height = std::numeric_limits<double>::infinity();
  for (const Vec3& p : view.rest_vertices) r.floor_height = std::min(r.floor_height, p.dot(up));
  r.contact = floor_contact(view.surface, Plane{r.floor_height * up, up}, {tolerance}).value();
  const Vec3 s = axis_vector((axis + 1) % 3), t = axis_vector((axis + 2) % 3);
  std::vector<std::vector<Vec2>> touching(parts.size());
  std::vector<Vec2> all;
  for (size_t i = 0; i < view.rest_vertices.size(); ++i) {
    const Vec3& x = view.rest_vertices[i];
    if (x.dot(up) > r.floor_height + tolerance) continue;
    touching[static_cast<size_t>(part_of_face[static_cast<size_t>(view.surface.vertex_points()[i].face)])].emplace_back(x.dot(s), x.dot(t));
    all.emplace_back(x.dot(s), x.dot(t));
  }
  r.rests.assign(parts.size(), 0);
  Vec3 centroid = Vec3::Zero();
  double area = 0.0;
  for (size_t k = 0; k < parts.size(); ++k) {
    const Part& part = parts[k];
    const Vec2 c(part.centroid.dot(s), part.centroid.dot(t));
    r.rests[k] = inside_margin(convex_hull(touching[k]), c) >= kMinMargin * (part.hi - part.lo).norm();
    centroid += part.area * part.centroid;
    area += part.area;
  }
  centroid /= area;
  r.margin = inside_margin(convex_hull(all), Vec2(centroid.dot(s), centroid.dot(t))) / size;
  if (std::getenv("SOFTSHELL_DEMO_DEBUG")) {
    std::fprintf(stderr, "rest on %c within %.3g: margin %.4f\n", 'x' + axis, tolerance, r.margin);
  }
  return r;
}

// Area, centroid and bounds of every part's rest limit surface (from the tessellation).
std::vector<Part> measure_parts(const View& view, const std::vector<int32_t>& part_of_face, int count) {
  std::vector<Part> parts(static_cast<size_t>(count));
  for (auto& p : parts) {
    p.lo = Vec3::Constant(std::numeric_limits<double>::infinity());
    p.hi = -p.lo;
  }
  const auto& x = view.rest_vertices;
  const auto& points = view.surface.vertex_points();
  for (size_t i = 0; i < x.size(); ++i) {
    Part& p = parts[static_cast<size_t>(part_of_face[static_cast<size_t>(points[i].face)])];
    p.lo = p.lo.cwiseMin(x[i]);
    p.hi = p.hi.cwiseMax(x[i]);
  }
  for (const auto& tri : view.surface.triangles()) {
    const Vec3 &a = x[static_cast<size_t>(tri[0])], &b = x[static_cast<size_t>(tri[1])], &c = x[static_cast<size_t>(tri[2])];
    Part& p = parts[static_cast<size_t>(part_of_face[static_cast<size_t>(points[static_cast<size_t>(tri[0])].face)])];
    const double area = 0.5 * (b - a).cross(c - a).norm();
    p.area += area;
    p.centroid += area * (a + b + c) / 3.0;
  }
  for (auto& p : parts) p.centroid = p.area > 0.0 ? Vec3(p.centroid / p.area) : Vec3(0.5 * (p.lo + p.hi));
  return parts;
}

// The up axis: +y (the OBJ convention) if the object rests on it, else the axis it rests on
// most stably (z-up files: CAD, OpenSubdiv's shapes); +y again if it rests on none.
int detect_up(const std::vector<Resting>& by_axis) {
  if (by_axis[1].margin >= kMinMargin) return 1;
  int best = 1;
  for (int a : {0, 2}) {
    if (by_axis[static_cast<size_t>(a)].margin > by_axis[static_cast<size_t>(best)].margin) best = a;
  }
  return by_axis[static_cast<size_t>(best)].margin >= kMinMargin ? best : -1;
}

// The up axis (given, or detected) and how the object rests there, at the smallest tolerance at
// which it rests; if it rests nowhere, +y (or the given axis) at the smallest tolerance.
std::pair<int, Resting> find_rest(const View& view, const Stage& stage, std::optional<int> up_axis) {
  std::optional<std::pair<int, Resting>> fallback;
  for (double tolerance : kContactTolerances) {
    std::vector<Resting> by_axis(3);
    for (int a = 0; a < 3; ++a) {
      by_axis[static_cast<size_t>(a)].margin = -1.0;
      if (!up_axis || *up_axis == a) {
        by_axis[static_cast<size_t>(a)] = rest_on(view, stage.part_of_face, stage.parts, a, stage.size, tolerance * stage.size);
      }
    }
    const int axis = up_axis ? *up_axis : detect_up(by_axis);
    if (axis >= 0 && by_axis[static_cast<size_t>(axis)].margin >= kMinMargin) return {axis, by_axis[static_cast<size_t>(axis)]};
    if (!fallback) fallback = {up_axis.value_or(1), by_axis[static_cast<size_t>(up_axis.value_or(1))]};
  }
  return *fallback;
}

// Three pins (limit points held where they are) that fix a part that cannot rest: far apart in
// its lower quarter, as tent pegs.
std::array<int32_t, 3> pin_samples(const View& view, const std::vector<int32_t>& part_of_face, int part, const Part& p,
                                   const Vec3& up) {
  const auto& x = view.rest_vertices;
  const auto& points = view.surface.vertex_points();
  const double low = p.lo.dot(up), high = p.hi.dot(up);
  std::vector<int32_t> candidates;
  for (size_t i = 0; i < x.size(); ++i) {
    if (part_of_face[static_cast<size_t>(points[i].face)] == part && x[i].dot(up) <= low + 0.25 * (high - low) + 1e-12) {
      candidates.push_back(static_cast<int32_t>(i));
    }
  }
  const auto farthest = [&](auto&& distance) {
    return *std::max_element(candidates.begin(), candidates.end(),
                             [&](int32_t a, int32_t b) { return distance(x[static_cast<size_t>(a)]) < distance(x[static_cast<size_t>(b)]); });
  };
  const Vec3 c = p.centroid;
  const int32_t a = farthest([&](const Vec3& q) { return (q - c - (q - c).dot(up) * up).norm(); });
  const Vec3 xa = x[static_cast<size_t>(a)];
  const int32_t b = farthest([&](const Vec3& q) { return (q - xa).norm(); });
  const Vec3 ab = (x[static_cast<size_t>(b)] - xa).normalized();
  const int32_t d = farthest([&](const Vec3& q) { return (q - xa - (q - xa).dot(ab) * ab).norm(); });
  return {a, b, d};
}

// Reachable samples: on the main part, clear of every support.
std::vector<char> reachable_samples(const View& view, const Stage& stage) {
  const auto& x = view.rest_vertices;
  const auto& points = view.surface.vertex_points();
  const Part& main = stage.parts[static_cast<size_t>(stage.main_part)];
  const double clearance = kReachClearance * (main.hi - main.lo).norm();
  std::vector<Vec3> supports = stage.floor_points;
  supports.insert(supports.end(), stage.pin_points.begin(), stage.pin_points.end());
  std::vector<char> out(x.size(), 0);
  for (double c : {clearance, 0.0}) {  // if nothing is clear of the supports, anything on the part
    for (size_t i = 0; i < x.size(); ++i) {
      if (stage.part_of_face[static_cast<size_t>(points[i].face)] != stage.main_part) continue;
      out[i] = std::all_of(supports.begin(), supports.end(), [&](const Vec3& s) { return (s - x[i]).norm() >= c; });
    }
    if (std::find(out.begin(), out.end(), 1) != out.end()) break;
  }
  return out;
}

// Whether limit points at `points` (all axes held) leave a rocking motion free: fewer than three
// of them, or all on one line.
bool may_rock(const std::vector<Vec3>& points, double size) {
  for (size_t i = 1; i < points.size(); ++i) {
    for (size_t j = i + 1; j < points.size(); ++j) {
      if ((points[i] - points[0]).cross(points[j] - points[0]).norm() > 1e-6 * size * size) return false;
    }
  }
  return true;
}

// At most kMaxFloorPoints of a part's contact points, spread over its contact region (farthest
// point sampling from the one furthest from its centroid): each costs the solver three rows.
std::vector<size_t> spread(const std::vector<size_t>& contacts, const FloorContact& contact, const View& view, const Part& part,
                           const Vec3& up) {
  if (contacts.size() <= static_cast<size_t>(Part::kMaxFloorPoints)) return contacts;
  std::vector<Vec3> x;
  for (size_t k : contacts) {
    const Vec3 p = view.evaluator.evaluate(contact.points[k]).position - part.centroid;
    x.push_back(p - p.dot(up) * up);
  }
  std::vector<double> distance(x.size());
  for (size_t i = 0; i < x.size(); ++i) distance[i] = x[i].norm();
  std::vector<size_t> out;
  while (out.size() < static_cast<size_t>(Part::kMaxFloorPoints)) {
    const size_t next = static_cast<size_t>(std::max_element(distance.begin(), distance.end()) - distance.begin());
    out.push_back(contacts[next]);
    for (size_t i = 0; i < x.size(); ++i) distance[i] = std::min(distance[i], (x[i] - x[next]).norm());
  }
  std::sort(out.begin(), out.end());
  return out;
}

// 3-2-1 pins: all of A's displacement, B's across the line AB, C's across the plane ABC: the six
// components that fix a rigid body and nothing more.
void pin(const View& view, Stage& stage, const std::array<int32_t, 3>& at) {
  const auto point = [&](int k) { return view.surface.vertex_points()[static_cast<size_t>(at[static_cast<size_t>(k)])]; };
  const auto x = [&](int k) { return view.rest_vertices[static_cast<size_t>(at[static_cast<size_t>(k)])]; };
  const Vec3 d = (x(1) - x(0)).normalized();
  const Vec3 n = d.cross(x(2) - x(0)).normalized();
  int along = 0, across = 0;
  d.cwiseAbs().maxCoeff(&along);
  n.cwiseAbs().maxCoeff(&across);
  stage.supports.limit_constraints.push_back({point(0), Vec3::Zero(), {}, {}});
  const auto lagrange = [&](int k, uint32_t axes) {
    auto rows = to_lagrange(view.evaluator, {point(k), Vec3::Zero(), {}, {}}, axes).value();
    stage.supports.lagrange_constraints.insert(stage.supports.lagrange_constraints.end(), rows.begin(), rows.end());
  };
  lagrange(1, kAxisAll & ~(1u << along));
  lagrange(2, 1u << across);
  for (int k = 0; k < 3; ++k) stage.pin_points.push_back(x(k));
  if (std::getenv("SOFTSHELL_DEMO_DEBUG")) {
    for (int k = 0; k < 3; ++k) {
      std::fprintf(stderr, "pin %d: face %d (%.3f %.3f %.3f)%s\n", k, point(k).face, x(k).x(), x(k).y(), x(k).z(),
                   k == 1 ? (" axes all but " + std::string(1, char('x' + along))).c_str() : k == 2 ? (" axis " + std::string(1, char('x' + across))).c_str() : "");
    }
  }
}

// The floor contacts of the parts that rest, every control point of the small ones, pins for
// the others.
void hold(const ControlMesh& mesh, const View& view, Stage& stage, const Resting& resting) {
  std::vector<std::vector<size_t>> contacts(stage.parts.size());
  for (size_t k = 0; k < resting.contact.points.size(); ++k) {
    contacts[static_cast<size_t>(stage.part_of_face[static_cast<size_t>(resting.contact.points[k].face)])].push_back(k);
  }
  std::vector<char> fixed(static_cast<size_t>(mesh.num_vertices()), 0);
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    if (stage.parts[static_cast<size_t>(stage.part_of_face[static_cast<size_t>(f)])].hold != Part::Hold::kFixed) continue;
    for (int32_t v : mesh.face(f)) fixed[static_cast<size_t>(v)] = 1;
  }
  for (int32_t v = 0; v < mesh.num_vertices(); ++v) {
    if (fixed[static_cast<size_t>(v)]) stage.supports.vertex_constraints.push_back({v, kAxisAll, Vec3::Zero()});
  }
  for (size_t p = 0; p < stage.parts.size(); ++p) {
    Part& part = stage.parts[p];
    if (part.hold == Part::Hold::kFloor) {
      part.touching = static_cast<int>(contacts[p].size());
      contacts[p] = spread(contacts[p], resting.contact, view, part, stage.up);
      std::vector<Vec3> at;
      for (size_t k : contacts[p]) at.push_back(view.evaluator.evaluate(resting.contact.points[k]).position);
      part.glued = may_rock(at, stage.size);
      for (size_t k : contacts[p]) {
        LimitConstraint c = resting.contact.limit_constraints[k];
        if (part.glued) c.du_displacement = c.dv_displacement = Vec3::Zero();
        stage.supports.limit_constraints.push_back(c);
      }
      stage.floor_points.insert(stage.floor_points.end(), at.begin(), at.end());
      part.floor_points = static_cast<int>(at.size());
    } else if (part.hold == Part::Hold::kPins) {
      pin(view, stage, pin_samples(view, stage.part_of_face, static_cast<int>(p), part, stage.up));
      part.pins = 3;
    }
  }
}

}  // namespace

View::View(const ControlMesh& mesh, int level)
    : evaluator(LimitEvaluator::create(mesh).value()),
      surface(Tessellation::create(evaluator, level).value()),
      picker(Picker::create(surface).value()),
      control(mesh.positions()),
      rest_vertices(surface.vertices()),
      rest_normals(surface.normals()) {}

void View::show(const std::vector<Vec3>& positions) {
  control = positions;
  surface.update(positions);
  picker.refit().value();
}

int32_t Stage::extreme(const std::vector<Vec3>& rest, const Vec3& direction, double band_lo, double band_hi) const {
  const Part& main = parts[static_cast<size_t>(main_part)];
  const double low = main.lo.dot(up), span = main.hi.dot(up) - low;
  const bool flat = span <= 1e-6 * size;
  int32_t best = -1;
  double best_value = -std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < rest.size(); ++i) {
    if (!reachable[i]) continue;
    const double h = flat ? 0.5 : (rest[i].dot(up) - low) / span;
    if (h < band_lo - 1e-9 || h > band_hi + 1e-9) continue;
    if (rest[i].dot(direction) > best_value) {
      best_value = rest[i].dot(direction);
      best = static_cast<int32_t>(i);
    }
  }
  // Nothing at those heights (a part of odd shape): anywhere the hand can reach.
  if (best < 0 && (band_lo > 0.0 || band_hi < 1.0)) return extreme(rest, direction, 0.0, 1.0);
  return best;
}

int Stage::resting_parts() const {
  return static_cast<int>(std::count_if(parts.begin(), parts.end(), [](const Part& p) { return p.hold == Part::Hold::kFloor; }));
}

std::string Stage::describe_supports() const {
  const auto count = [](size_t n, const std::string& what) { return std::to_string(n) + " " + what + (n == 1 ? "" : "s"); };
  const int resting = resting_parts();
  const int pinned = static_cast<int>(parts.size()) - resting - fixed_parts;
  const bool glued = std::any_of(parts.begin(), parts.end(), [](const Part& p) { return p.glued; });
  char within[48];
  std::snprintf(within, sizeof within, " within %.3g mm of it", contact_tolerance * 1000.0);
  int touching = 0;
  for (const Part& p : parts) touching += p.touching;
  const std::string floor = (touching > static_cast<int>(floor_points.size()) ? "held at " + std::to_string(floor_points.size()) +
                                                                                   " of its " + count(static_cast<size_t>(touching), "contact point")
                                                                             : count(floor_points.size(), "contact point")) +
                            within + (glued ? ", held flat" : "");
  if (parts.size() == 1) {
    return resting ? "rests on the floor (" + floor + ")" : "cannot rest on the floor stably: held by 3 pins";
  }
  std::vector<std::string> out;
  if (resting) out.push_back(count(static_cast<size_t>(resting), "part") + " resting on the floor (" + floor + ")");
  if (pinned) out.push_back(count(static_cast<size_t>(pinned), "part") + " that cannot rest held by 3 pins each");
  if (fixed_parts) {
    out.push_back(count(static_cast<size_t>(fixed_parts), "small part") + " (at most " + std::to_string(Part::kFixedPart) +
                  " control points, too coarse to bend) fixed");
  }
  std::string joined = std::to_string(parts.size()) + " parts: ";
  for (size_t k = 0; k < out.size(); ++k) joined += (k ? ", " : "") + out[k];
  return joined;
}

Stage adapt_to_object(const ControlMesh& mesh, const View& view, std::optional<int> up_axis) {
  Stage stage;
  int count = 0;
  stage.part_of_face = parts_of_faces(mesh, count);
  stage.parts = measure_parts(view, stage.part_of_face, count);
  std::vector<int32_t> part_of_vertex(static_cast<size_t>(mesh.num_vertices()), -1);  // parts share no control point
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    for (int32_t v : mesh.face(f)) part_of_vertex[static_cast<size_t>(v)] = stage.part_of_face[static_cast<size_t>(f)];
  }
  for (int32_t p : part_of_vertex) {
    if (p >= 0) ++stage.parts[static_cast<size_t>(p)].control_points;
  }
  // The hands go to the part with the most control points (the most to bend), the larger on a tie.
  stage.main_part = static_cast<int>(std::max_element(stage.parts.begin(), stage.parts.end(),
                                                      [](const Part& a, const Part& b) {
                                                        return a.control_points < b.control_points ||
                                                               (a.control_points == b.control_points && a.area < b.area);
                                                      }) -
                                     stage.parts.begin());
  // Supports take at least six of its displacement components, a turning hand nine more.
  if (const int n = stage.parts[static_cast<size_t>(stage.main_part)].control_points; n < Part::kMinHandled) {
    fail(ErrorCode::kUnprocessable, "the mesh is too coarse for the scripted hands: its largest part has only " +
                                        std::to_string(n) + " control points, and holding it and turning a point of it takes " +
                                        std::to_string(Part::kMinHandled) + " (subdivide it once, e.g. in Blender, and try again)");
  }
  stage.lo = Vec3::Constant(std::numeric_limits<double>::infinity());
  stage.hi = -stage.lo;
  for (const Vec3& p : view.rest_vertices) {
    stage.lo = stage.lo.cwiseMin(p);
    stage.hi = stage.hi.cwiseMax(p);
  }
  stage.centre = 0.5 * (stage.lo + stage.hi);
  stage.size = (stage.hi - stage.lo).norm();

  stage.up_detected = !up_axis;
  const auto [axis, resting] = find_rest(view, stage, up_axis);
  stage.up_axis = axis;
  stage.contact_tolerance = resting.tolerance;
  stage.up = axis_vector(stage.up_axis);
  const int a1 = (stage.up_axis + 1) % 3, a2 = (stage.up_axis + 2) % 3;
  stage.e1 = axis_vector(stage.hi[a1] - stage.lo[a1] >= stage.hi[a2] - stage.lo[a2] ? a1 : a2);
  stage.e2 = stage.up.cross(stage.e1);
  stage.height = stage.hi[stage.up_axis] - stage.lo[stage.up_axis];
  stage.floor_height = resting.floor_height;
  for (size_t k = 0; k < stage.parts.size(); ++k) {
    Part& part = stage.parts[k];
    part.hold = part.control_points <= Part::kFixedPart && k != static_cast<size_t>(stage.main_part) ? Part::Hold::kFixed
                : resting.rests[k]                                                                   ? Part::Hold::kFloor
                                                                                                      : Part::Hold::kPins;
    stage.fixed_parts += part.hold == Part::Hold::kFixed;
  }
  hold(mesh, view, stage, resting);
  stage.reachable = reachable_samples(view, stage);
  return stage;
}

}  // namespace softshell::demo
