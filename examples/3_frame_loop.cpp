// Example 3: the asynchronous frame loop. A game never waits for the solver: every frame it
// checks (without blocking) whether the deformation in flight is done, shows the newest result,
// and sends the hand's newest pose when nothing is in flight. Here a hand circles above the free
// end of a plate clamped at one edge, for one second at 60 frames per second.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <future>
#include <thread>
#include <vector>

#include "softshell/embedded_session.h"
#include "softshell/interaction.h"
#include "softshell/tessellation.h"

using namespace softshell;
using namespace std::chrono_literals;

int main() try {
  // A 1 m x 0.5 m steel plate, 2 mm thick, 10 x 5 faces; its edge x = 0 is clamped (the first
  // two columns of control points fixed).
  const int nx = 10, ny = 5;
  auto index = [&](int i, int j) { return j * (nx + 1) + i; };
  std::vector<Vec3> points;
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i) points.emplace_back(1.0 * i / nx, 0.5 * j / ny, 0.0);
  std::vector<std::vector<int32_t>> quads;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) quads.push_back({index(i, j), index(i + 1, j), index(i + 1, j + 1), index(i, j + 1)});
  const ControlMesh mesh(points, quads);
  DeformationRequest clamp;
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i < 2; ++i) clamp.vertex_constraints.push_back({index(i, j), kAxisAll, Vec3::Zero()});

  EmbeddedSession session;
  const GeomId id = session.upload(mesh, material_preset("steel", 0.002).value()).value().id;

  // The hand grabs the middle of the free edge.
  const LimitEvaluator surface = LimitEvaluator::create(mesh).value();
  Tessellation shown = Tessellation::create(surface, 2).value();  // what is drawn
  const SurfacePoint tip{(ny / 2) * nx + nx - 1, 0, 1.0, 0.5};   // last face of the middle row, u = 1
  Pose hand;
  hand.position = surface.evaluate(tip).position;
  const Vec3 start = hand.position;
  const Grab grab = Grab::begin(surface, tip, mesh.positions(), hand).value();

  std::future<Result<DeformationResult>> in_flight;  // at most one request at a time
  Pose sent;                                         // the hand pose of the request in flight
  DeformationRequest request;
  int frames = 0, shown_results = 0, frames_waiting = 0;
  auto next_frame = std::chrono::steady_clock::now();
  for (; frames < 60; ++frames) {
    // Input: the hand moves on a circle of 3 cm radius in the plane x = const.
    const double angle = 2.0 * 3.14159265358979 * frames / 60.0;
    hand.position = start + Vec3(0.0, 0.03 * std::sin(angle), 0.03 * (1.0 - std::cos(angle)));

    // 1. A result arrived? Show it (wait_for(0s) never blocks).
    if (in_flight.valid() && in_flight.wait_for(0s) == std::future_status::ready) {
      const DeformationResult result = in_flight.get().value();
      shown.update(result.positions);  // and upload shown.vertices() / normals() to the GPU
      ++shown_results;
    } else if (in_flight.valid()) {
      ++frames_waiting;
    }
    // 2. Nothing in flight: send the newest pose. deform_async returns at once.
    if (!in_flight.valid()) {
      request = clamp;
      request.limit_constraints.push_back(grab.constraint(hand));
      in_flight = session.deform_async(id, request);
      sent = hand;
    }
    // 3. The rest of the frame (physics, rendering ...), then wait for the next one.
    next_frame += std::chrono::microseconds(16667);
    std::this_thread::sleep_until(next_frame);
  }

  // Leaving: the last request is still answered; it put the tip where its hand was.
  const DeformationResult last = in_flight.get().value();
  const double miss = (surface.evaluate(tip, last.positions).position - grab.target(sent)).norm();
  std::printf("frame loop: %d frames, %d results shown, %d frames drawn while a solve was running; last miss %.1e m\n",
              frames, shown_results, frames_waiting, miss);
  return shown_results > 0 && miss < 1e-6 ? 0 : 1;
} catch (const Exception& e) {
  std::fprintf(stderr, "frame loop: %s\n", e.what());
  return 1;
}
