// Hold updates benchmark (README "Numbers"): 1, 4 and 16 clients each updating its own hold at
// 60 Hz (a grab that follows a moving hand) on catmark_righthanded and spot_quadrangulated, on
// top of a "floor" hold (the lowest 5% of the control points). Per run: the answer latency of a
// PUT (sent -> the first result that includes it), the hold-state solves per second, and the
// updates merged per solve.
//
// Each client sends its next update at the next 60 Hz tick after its previous answer (a frame
// loop that never has two updates in flight); ticks missed while waiting are skipped and counted.
// Binary bodies and answers, keep-alive connections, server in-process, loopback.
//
// usage: bench_holds [seconds per run, default 3]
#include <algorithm>
#include <atomic>
#include <cstdio>
#include <mutex>
#include <random>
#include <thread>

#include "bench_support.h"
#include "softshell/http/server.h"
#include "softshell/limit_evaluator.h"
#include "softshell/service/service.h"
#include "softshell/wire.h"
#include "test_meshes.h"

#include <httplib.h>  // last: its <resolv.h> defines a macro `_res` that breaks Eigen

using namespace softshell;

namespace {

constexpr const char* kBin = "application/octet-stream";

struct Scene {
  std::string name;
  ControlMesh mesh;
  GeomId id;
  DeformationRequest floor;
  std::vector<char> held;
  std::shared_ptr<LimitEvaluator> evaluator;
  std::vector<int32_t> free_faces;  // faces whose stencil touches no held point
};

// A client's grab at `t` seconds: a Lagrange constraint on its own limit point (binary layout),
// moving along a small circle.
DeformationRequest hand(const Scene& s, int client, double t) {
  const int32_t face = s.free_faces[static_cast<size_t>(client * 7919) % s.free_faces.size()];
  const LimitStencil st = s.evaluator->stencil(SurfacePoint{face, 0, 0.5, 0.5});
  LagrangeConstraint c;
  c.indices = st.indices;
  for (double w : st.position) c.coefficients.push_back(Vec3(w, w, w));
  const double phase = 6.2831853 * (0.5 * t + 0.1 * client);
  c.values = Vec3(0.005 * std::cos(phase), 0.01, 0.005 * std::sin(phase));
  DeformationRequest r;
  r.lagrange_constraints.push_back(std::move(c));
  return r;
}

std::unique_ptr<httplib::Client> client(int port) {
  auto c = std::make_unique<httplib::Client>("127.0.0.1", port);
  c->set_keep_alive(true);
  c->set_tcp_nodelay(true);
  c->set_read_timeout(120, 0);
  return c;
}

}  // namespace

int main(int argc, char** argv) {
  const double seconds = argc > 1 ? std::atof(argv[1]) : 3.0;
  auto svc = std::make_shared<service::Service>(service::ServiceOptions{});
  http::ServerOptions ho;
  ho.logger = {};
  http::HttpServer server(svc, ho);
  const int port = server.start("127.0.0.1", 0).value();
  std::printf("softshell hold updates on %s, loopback, server in-process; clients at 60 Hz, %.0f s per run\n\n",
              bench::machine().c_str(), seconds);

  std::vector<Scene> scenes;
  const Material material{6.9e10, 0.32, 0.002, 2700.0};
  for (const char* name : {"catmark_righthanded.obj", "spot_quadrangulated.obj"}) {
    Scene s;
    s.name = name;
    s.mesh = test::load_asset_mesh(name);
    const double scale = 1.0 / s.mesh.bounding_diagonal();
    for (Vec3& p : s.mesh.positions()) p *= scale;
    std::vector<std::pair<double, int32_t>> by_height;
    for (int32_t i = 0; i < s.mesh.num_vertices(); ++i) by_height.push_back({s.mesh.positions()[i].y(), i});
    std::sort(by_height.begin(), by_height.end());
    s.held.assign(by_height.size(), 0);
    for (size_t k = 0; k < std::max<size_t>(3, by_height.size() / 20); ++k) {
      s.floor.vertex_constraints.push_back({by_height[k].second, kAxisAll, Vec3::Zero()});
      s.held[static_cast<size_t>(by_height[k].second)] = 1;
    }
    s.evaluator = std::make_shared<LimitEvaluator>(LimitEvaluator::create(s.mesh).value());
    for (int32_t f = 0; f < s.mesh.num_faces(); ++f) {
      if (s.mesh.face_size(f) != 4) continue;
      bool free = true;
      for (int32_t v : s.evaluator->support(f)) free = free && !s.held[static_cast<size_t>(v)];
      if (free) s.free_faces.push_back(f);
    }
    // Spread the clients' faces over the mesh.
    std::shuffle(s.free_faces.begin(), s.free_faces.end(), std::mt19937(3));
    s.id = svc->upload(s.mesh, material).value().id;
    (void)svc->wait_until_precomputed(s.id, std::chrono::minutes(5));
    auto c = client(port);
    auto r = c->Put(("/geometries/" + s.id.hex() + "/holds/floor?ttl=600").c_str(), {{"Accept", kBin}},
                    wire::encode_request_binary(s.floor).value(), kBin);
    if (!r || r->status != 200) {
      std::printf("%s: the floor hold failed\n", name);
      return 1;
    }
    std::printf("%s: %d control points, %zu held by the floor hold\n", name, s.mesh.num_vertices(),
                s.floor.vertex_constraints.size());
    scenes.push_back(std::move(s));
  }

  std::printf("\n| mesh | clients | updates | per client /s | missed ticks | answer p50 | p95 | hold-state solves/s | "
              "updates per solve | solve mean |\n| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  for (const Scene& s : scenes) {
    for (int clients : {1, 4, 16}) {
      // Every client's hold exists before the timing starts.
      for (int k = 0; k < clients; ++k) {
        auto c = client(port);
        (void)c->Put(("/geometries/" + s.id.hex() + "/holds/hand-" + std::to_string(k)).c_str(), {{"Accept", kBin}},
                     wire::encode_request_binary(hand(s, k, 0.0)).value(), kBin);
      }
      const auto before = svc->stats();
      std::mutex mu;
      std::vector<double> latencies;
      std::atomic<int> missed{0}, failed{0};
      std::vector<std::thread> threads;
      const auto start = bench::Clock::now() + std::chrono::milliseconds(50);
      const auto end = start + std::chrono::duration_cast<bench::Clock::duration>(std::chrono::duration<double>(seconds));
      for (int k = 0; k < clients; ++k) {
        threads.emplace_back([&, k] {
          auto c = client(port);
          const std::string path = "/geometries/" + s.id.hex() + "/holds/hand-" + std::to_string(k);
          const auto tick = std::chrono::duration_cast<bench::Clock::duration>(std::chrono::duration<double>(1.0 / 60));
          auto next = start + tick * (k % 4) / 4;  // clients not in lockstep
          std::vector<double> mine;
          while (next < end) {
            std::this_thread::sleep_until(next);
            const auto sent = bench::Clock::now();
            const double t = std::chrono::duration<double>(sent - start).count();
            auto r = c->Put(path.c_str(), {{"Accept", kBin}}, wire::encode_request_binary(hand(s, k, t)).value(), kBin);
            if (!r || r->status != 200) {
              failed.fetch_add(1);
              continue;
            }
            mine.push_back(bench::ms_since(sent));
            next += tick;
            while (next < bench::Clock::now()) {
              next += tick;
              missed.fetch_add(1);
            }
          }
          std::lock_guard lock(mu);
          latencies.insert(latencies.end(), mine.begin(), mine.end());
        });
      }
      for (auto& t : threads) t.join();
      const double wall = std::chrono::duration<double>(bench::Clock::now() - start).count();
      const auto after = svc->stats();
      const double solves = static_cast<double>(after.hold_solves - before.hold_solves);
      const double changes = static_cast<double>(after.hold_changes_solved - before.hold_changes_solved);
      // Solve time of this run's hold-state solves, from the histogram's bucket counts.
      service::Histogram::Snapshot d = after.hold_solve_seconds;
      for (size_t b = 0; b < d.buckets.size(); ++b) d.buckets[b] -= before.hold_solve_seconds.buckets[b];
      d.count -= before.hold_solve_seconds.count;
      d.sum -= before.hold_solve_seconds.sum;
      std::printf("| %s | %d | %zu | %.1f | %d | %.2f ms | %.2f ms | %.0f | %.2f | %.2f ms |%s\n",
                  s.name.c_str(), clients, latencies.size(), static_cast<double>(latencies.size()) / wall / clients,
                  missed.load(), bench::percentile(latencies, 0.5), bench::percentile(latencies, 0.95), solves / wall,
                  solves > 0 ? changes / solves : 0.0, d.count ? 1e3 * d.sum / static_cast<double>(d.count) : 0.0,
                  failed.load() ? (" " + std::to_string(failed.load()) + " failed").c_str() : "");
      std::fflush(stdout);
    }
  }
  server.stop();
  return 0;
}
