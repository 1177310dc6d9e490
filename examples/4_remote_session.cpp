// Example 4: a remote session. Two clients share one softshell server over HTTP: the first uploads
// a plate and deforms it, the second follows its results with latest_result (a long poll), as a
// second device or viewer would. Give the server's URL (softshell-server prints it when it
// starts), or nothing to open a server inside this program on a free port.
#include <chrono>
#include <cstdio>
#include <future>
#include <memory>
#include <string>
#include <vector>

#include "softshell/embedded_session.h"
#include "softshell/remote_session.h"

using namespace softshell;
using namespace std::chrono_literals;

int main(int argc, char** argv) try {
  std::unique_ptr<EmbeddedSession> local;  // only without a URL
  std::string url;
  if (argc > 1) {
    url = argv[1];
  } else {
    local = std::make_unique<EmbeddedSession>();
    url = "http://127.0.0.1:" + std::to_string(local->listen("127.0.0.1", 0).value());
  }
  // connect() checks GET /health: an unreachable server is an error here, not at the first call.
  RemoteSessionOptions options;
  options.format = wire::Format::kJson;  // full double precision (kBinary: the paper's f32 layouts)
  const std::unique_ptr<RemoteSession> master = RemoteSession::connect(url, options).value();
  const std::unique_ptr<RemoteSession> viewer = RemoteSession::connect(url, options).value();

  // A 4 x 4 plate, 0.5 mm copper, its boundary fixed.
  const int n = 4;
  std::vector<Vec3> points;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) points.emplace_back(0.1 * i, 0.1 * j, 0.0);
  std::vector<std::vector<int32_t>> quads;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i)
      quads.push_back({j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i});
  const ControlMesh mesh(points, quads);
  const UploadResult uploaded = master->upload(mesh, material_preset("copper", 0.0005).value()).value();
  std::printf("remote: %s holds geometry %s\n", url.c_str(), uploaded.id.hex().c_str());

  // The viewer waits (up to 10 s) for a result newer than the one it has (none: 0).
  std::future<Result<std::optional<DeformationResult>>> followed =
      std::async(std::launch::async, [&] { return viewer->latest_result(uploaded.id, 0, 10s); });

  // The master presses the middle control point with 2 N.
  DeformationRequest request;
  for (int k = 0; k < mesh.num_vertices(); ++k) {
    const int i = k % (n + 1), j = k / (n + 1);
    if (i == 0 || j == 0 || i == n || j == n) request.vertex_constraints.push_back({k, kAxisAll, Vec3::Zero()});
  }
  const int middle = (n / 2) * (n + 1) + n / 2;
  request.forces.push_back({middle, Vec3(0, 0, -2.0)});
  const DeformationResult result = master->deform(uploaded.id, request).value();

  const std::optional<DeformationResult> seen = followed.get().value();
  const bool same = seen && seen->res_id == result.res_id && seen->positions == result.positions;
  std::printf("remote: result %u moved the middle %.3f mm down; the viewer got result %u %s\n", result.res_id,
              1e3 * (points[middle].z() - result.positions[middle].z()), seen ? seen->res_id : 0u,
              same ? "(the same positions)" : "(DIFFERENT)");
  return same ? 0 : 1;
} catch (const Exception& e) {
  std::fprintf(stderr, "remote session: %s\n", e.what());
  return 1;
}
