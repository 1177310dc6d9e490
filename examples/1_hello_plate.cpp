// Example 1: hello plate. A square aluminium plate, simply supported on its four edges, carries a
// uniform load; one solve gives its deflection, compared with Kirchhoff plate theory
// (Timoshenko & Woinowsky-Krieger, Theory of Plates and Shells, Table 8: w = 0.00406 q a^4 / D).
#include <cmath>
#include <cstdio>
#include <vector>

#include "softshell/embedded_session.h"  // EmbeddedSession: the simulation server in this process

using namespace softshell;

int main() try {
  // 1. A control mesh: n x n quads over [0, a]^2 in the plane z = 0. Lengths are metres.
  const int n = 16;
  const double a = 1.0;
  auto index = [&](int i, int j) { return j * (n + 1) + i; };
  std::vector<Vec3> points;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) points.emplace_back(a * i / n, a * j / n, 0.0);
  std::vector<std::vector<int32_t>> quads;  // counter-clockwise seen from +z
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) quads.push_back({index(i, j), index(i + 1, j), index(i + 1, j + 1), index(i, j + 1)});
  const ControlMesh mesh(points, quads);

  // 2. A material: 1 cm aluminium (SI units: E in Pa, thickness in m).
  const Material material = material_preset("aluminium", 0.01).value();  // value() throws on an error

  // 3. Upload it: the server precomputes the shell's stiffness once per geometry.
  EmbeddedSession session;
  const GeomId id = session.upload(mesh, material).value().id;

  // 4. The request. Simple supports: the boundary control points do not move; the others may only
  //    move along z (a plate under a transverse load has no in-plane motion). 1 kPa downwards.
  DeformationRequest request;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const bool boundary = i == 0 || j == 0 || i == n || j == n;
      request.vertex_constraints.push_back({index(i, j), boundary ? uint32_t{kAxisAll} : kAxisX | kAxisY, Vec3::Zero()});
    }
  const double q = 1000.0;  // N/m^2
  request.surface_load = Vec3(0, 0, -q);

  // 5. Solve. The result holds the deformed control points.
  const DeformationResult result = session.deform(id, request).value();

  // 6. The surface is the limit of the control mesh: evaluate it at the plate's centre (the corner
  //    (u, v) = (0, 0) of face (n/2, n/2)) for the deformed control points.
  const LimitEvaluator surface = LimitEvaluator::create(mesh).value();
  const SurfacePoint centre{(n / 2) * n + n / 2, 0, 0.0, 0.0};  // face (i, j) is number j * n + i
  const double w = -surface.evaluate(centre, result.positions).position.z();

  const double D = material.bending_stiffness();  // E t^3 / (12 (1 - nu^2))
  const double reference = 0.00406 * q * std::pow(a, 4) / D;
  std::printf("hello plate: centre deflection %.4f mm, Kirchhoff plate theory %.4f mm (%+.2f%%)\n", 1e3 * w,
              1e3 * reference, 100.0 * (w / reference - 1.0));
  return std::abs(w / reference - 1.0) < 0.01 ? 0 : 1;  // agrees within 1%
} catch (const Exception& e) {  // what value() throws: a code and a message for people
  std::fprintf(stderr, "hello plate: %s\n", e.what());
  return 1;
}
