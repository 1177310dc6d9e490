// Example 2: pick and grab. Loads a control mesh (an OBJ file, y up, metres), stands it on the
// floor, shoots a ray at it from above, grabs the point the ray hits and lifts it by 5 cm. The
// deformed limit surface then passes exactly through the hand's target.
#include <cstdio>

#include "softshell/embedded_session.h"
#include "softshell/interaction.h"  // floor_contact, Grab
#include "softshell/obj_io.h"
#include "softshell/picking.h"      // Picker, Ray
#include "softshell/tessellation.h"

using namespace softshell;

int main(int argc, char** argv) try {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s MESH.obj   (e.g. share/softshell/assets/meshes/spot_control_mesh.obj)\n", argv[0]);
    return 2;
  }
  const ControlMesh mesh = read_obj(argv[1]).value();

  // What the application shows: the limit surface as triangles, and a picker (a BVH) over them.
  const LimitEvaluator surface = LimitEvaluator::create(mesh).value();
  Tessellation shown = Tessellation::create(surface, 3).value();
  Picker picker = Picker::create(shown).value();

  // Its extent, and the floor under its lowest point (y up).
  Vec3 lo = shown.vertices().front(), hi = lo;
  for (const Vec3& v : shown.vertices()) lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
  FloorOptions touching;
  touching.tolerance = 0.01;  // points up to 1 cm above the floor stand on it: spot's four feet
  const FloorContact floor = floor_contact(shown, Plane{lo, Vec3::UnitY()}, touching).value();
  std::printf("floor: %zu points hold the object (%s)\n", floor.points.size(),
              floor.fixes_rigid_motion ? "it cannot move as a rigid body" : "it could still slide or tip");

  // A ray straight down through the middle of the object picks a point of the limit surface.
  Ray ray;
  ray.origin = Vec3(0.5 * (lo.x() + hi.x()), hi.y() + 1.0, 0.5 * (lo.z() + hi.z()));
  ray.direction = Vec3(0, -1, 0);
  const std::optional<Pick> pick = picker.pick(ray).value();
  if (!pick) {
    std::fprintf(stderr, "the ray missed the object\n");
    return 1;
  }

  // Grab it with a hand where the ray hit, then lift the hand 5 cm.
  Pose hand;
  hand.position = pick->position;
  const Grab grab = Grab::begin(surface, pick->point, mesh.positions(), hand).value();
  hand.position.y() += 0.05;

  // The request: stay on the floor, and the grabbed point follows the hand.
  DeformationRequest request;
  floor.add_to(request);
  request.limit_constraints.push_back(grab.constraint(hand));

  EmbeddedSession session;
  const GeomId id = session.upload(mesh, material_preset("rubber", 0.01).value()).value().id;
  const DeformationResult result = session.deform(id, request).value();

  // Show the result: move the triangles to the deformed limit surface and refit the picker.
  shown.update(result.positions);
  picker.refit().value();

  const Vec3 reached = surface.evaluate(pick->point, result.positions).position;
  const double miss = (reached - grab.target(hand)).norm();
  std::printf("picked (%.3f, %.3f, %.3f) on face %d, lifted to y = %.3f m; the surface is %.1e m from the hand\n",
              pick->position.x(), pick->position.y(), pick->position.z(), pick->point.face, reached.y(), miss);
  return floor.fixes_rigid_motion && miss < 1e-6 ? 0 : 1;
} catch (const Exception& e) {
  std::fprintf(stderr, "pick and grab: %s\n", e.what());
  return 1;
}
