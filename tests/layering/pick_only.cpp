// A plug-in that only picks: reads a control mesh, tessellates it and picks a point with a ray,
// linked against softshell::interaction alone. tests/layering checks that this program's runtime
// closure holds no networking or hashing library (no OpenSSL, no cpp-httplib).
#include <cstdio>

#include "softshell/limit_evaluator.h"
#include "softshell/obj_io.h"
#include "softshell/picking.h"
#include "softshell/tessellation.h"

int main(int argc, char** argv) {
  using namespace softshell;
  if (argc != 2) {
    std::fprintf(stderr, "usage: pick_only MESH.obj\n");
    return 2;
  }
  const Result<ControlMesh> mesh = read_obj(argv[1]);
  if (!mesh) {
    std::fprintf(stderr, "%s\n", mesh.error().message.c_str());
    return 1;
  }
  const LimitEvaluator evaluator = LimitEvaluator::create(*mesh).value();
  const Tessellation tessellation = Tessellation::create(evaluator, 2).value();
  const Picker picker = Picker::create(tessellation).value();
  // A ray from far outside toward the centre of the bounding box hits the surface.
  Vec3 low, high;
  mesh->bounding_box(low, high);
  const Vec3 centre = 0.5 * (low + high);
  Ray ray;
  ray.origin = centre + Vec3(0.0, 0.0, 2.0 * (high - low).norm() + 1.0);
  ray.direction = -Vec3::UnitZ();
  const auto pick = picker.pick(ray).value();
  if (!pick) {
    std::fprintf(stderr, "the ray missed\n");
    return 1;
  }
  std::printf("face %d subface %d u %.6f v %.6f\n", pick->point.face, pick->point.subface, pick->point.u, pick->point.v);
  return 0;
}
