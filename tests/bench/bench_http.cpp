// End-to-end HTTP benchmark over loopback (README table beside the paper's Fig. 9 and Fig. 11):
//  - latency of one deformation (a new grab point every time) in binary and JSON, against the
//    solve time on the server, for the meshes of the engine benchmark;
//  - throughput with 1, 2 and 8 concurrent clients;
//  - long-poll wake-up latency (result stored -> waiting client has it);
//  - bytes on the wire per request and per result, against sending a level-2 triangulation.
//
// usage: bench_http [deformations per mesh, default 40]
#include <atomic>
#include <mutex>
#include <cstdio>
#include <random>
#include <thread>

#include "bench_support.h"
#include "softshell/http/server.h"
#include "softshell/limit_evaluator.h"
#include "softshell/service/service.h"
#include "softshell/tessellation.h"
#include "softshell/wire.h"
#include "test_meshes.h"

#include <httplib.h>  // last: its <resolv.h> defines a macro `_res` that breaks Eigen

using namespace softshell;

namespace {

constexpr const char* kBin = "application/octet-stream";
constexpr const char* kJson = "application/json";

struct Scene {
  std::string name;
  ControlMesh mesh;
  GeomId id;
  DeformationRequest supports;  // bottom 5% of the control points held
  std::vector<char> held;       // per control point
  std::shared_ptr<LimitEvaluator> evaluator;
};

// A request: the supports plus a grab of a random limit point (a Lagrange constraint built from
// the client's own limit stencil, the same in both formats).
DeformationRequest grab(const Scene& s, std::mt19937& rng) {
  DeformationRequest r = s.supports;
  // A face none of whose stencil points is held (a grab among the supports would contradict them).
  int32_t face = 0;
  for (;;) {
    face = static_cast<int32_t>(rng() % static_cast<unsigned>(s.mesh.num_faces()));
    bool free = true;
    for (int32_t v : s.evaluator->support(face)) free = free && !s.held[static_cast<size_t>(v)];
    if (free) break;
  }
  const SurfacePoint p{face, 0, 0.5, 0.5};
  const LimitStencil st = s.evaluator->stencil(p);
  LagrangeConstraint c;
  c.indices = st.indices;
  for (double w : st.position) c.coefficients.push_back(Vec3(w, w, w));
  c.values = Vec3(0.0, 0.01, 0.005);
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

httplib::Headers headers(const char* accept) { return {{"Accept", accept}, {"Accept-Encoding", "identity"}}; }

}  // namespace

int main(int argc, char** argv) {
  const int solves = argc > 1 ? std::atoi(argv[1]) : 40;
  auto svc = std::make_shared<service::Service>(service::ServiceOptions{});
  http::HttpServer server(svc);
  const int port = server.start("127.0.0.1", 0).value();
  std::printf("softshell HTTP benchmark on %s, loopback, server in-process (port %d)\n\n", bench::machine().c_str(),
              port);

  // --- scenes ------------------------------------------------------------------------------------
  std::vector<Scene> scenes;
  const Material material{6.9e10, 0.32, 0.002, 2700.0};
  for (const char* name : {"catmark_righthanded.obj", "spot_quadrangulated.obj", "blub_quadrangulated.obj"}) {
    Scene s;
    s.name = name;
    s.mesh = test::load_asset_mesh(name);
    const double scale = 1.0 / s.mesh.bounding_diagonal();
    for (Vec3& p : s.mesh.positions()) p *= scale;
    // Hold the lowest 5% of the control points (y up).
    std::vector<std::pair<double, int32_t>> by_height;
    for (int32_t i = 0; i < s.mesh.num_vertices(); ++i) by_height.push_back({s.mesh.positions()[i].y(), i});
    std::sort(by_height.begin(), by_height.end());
    s.held.assign(by_height.size(), 0);
    for (size_t k = 0; k < std::max<size_t>(3, by_height.size() / 20); ++k) {
      s.supports.vertex_constraints.push_back({by_height[k].second, kAxisAll, Vec3::Zero()});
      s.held[static_cast<size_t>(by_height[k].second)] = 1;
    }
    s.evaluator = std::make_shared<LimitEvaluator>(LimitEvaluator::create(s.mesh).value());
    auto t0 = bench::Clock::now();
    auto c = client(port);
    auto up = c->Post("/geometries", headers(kJson), wire::encode_geometry_json(s.mesh, material), kJson);
    if (!up || up->status >= 300) {
      std::printf("%s: upload failed\n", name);
      return 1;
    }
    s.id = wire::decode_upload_response_json(up->body, true).value().id;
    const auto info = svc->wait_until_precomputed(s.id, std::chrono::minutes(5)).value();
    std::printf("%s: %d control points, %d faces, uploaded and precomputed in %.0f ms (%s)\n", name,
                s.mesh.num_vertices(), s.mesh.num_faces(), bench::ms_since(t0), std::string(to_string(info.status)).c_str());
    scenes.push_back(std::move(s));
  }

  // --- latency -----------------------------------------------------------------------------------
  std::printf("\n| mesh | DOFs | format | request bytes | result bytes | end-to-end p50 | p95 | server solve p50 | "
              "HTTP + codec overhead p50 |\n| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  for (const Scene& s : scenes) {
    std::mt19937 rng(7);
    auto c = client(port);
    const std::string path = "/geometries/" + s.id.hex() + "/results";
    // First solve factorizes K with the supports eliminated; not timed.
    c->Post(path, headers(kBin), wire::encode_request_binary(grab(s, rng)).value(), kBin);
    for (const bool binary : {true, false}) {
      std::vector<double> e2e, solve;
      size_t request_bytes = 0, result_bytes = 0;
      for (int i = 0; i < solves; ++i) {
        const DeformationRequest r = grab(s, rng);
        const auto t0 = bench::Clock::now();
        const std::string body = binary ? wire::encode_request_binary(r).value() : wire::encode_request_json(r);
        auto res = c->Post(path, headers(binary ? kBin : kJson), body, binary ? kBin : kJson);
        if (!res || res->status != 200) {
          std::printf("| %s | request failed: %s |\n", s.name.c_str(), res ? res->body.c_str() : "no answer");
          break;
        }
        auto result = binary ? wire::decode_result_binary(res->body) : wire::decode_result_json(res->body);
        e2e.push_back(bench::ms_since(t0));
        request_bytes = body.size();
        result_bytes = res->body.size();
        solve.push_back(svc->result(s.id, result->res_id).value()->stats.solve_ms);
      }
      std::vector<double> overhead(e2e.size());
      for (size_t i = 0; i < e2e.size(); ++i) overhead[i] = e2e[i] - solve[i];
      std::printf("| %s | %d | %s | %zu | %zu | %.2f ms | %.2f ms | %.2f ms | %.2f ms |\n", s.name.c_str(),
                  3 * s.mesh.num_vertices(), binary ? "binary" : "JSON", request_bytes, result_bytes,
                  bench::percentile(e2e, 0.5), bench::percentile(e2e, 0.95), bench::percentile(solve, 0.5),
                  bench::percentile(overhead, 0.5));
      std::fflush(stdout);
    }
  }

  // --- bytes per result against a level-2 triangulation ----------------------------------------
  std::printf("\n| mesh | result (binary) | result (JSON) | level-2 triangulation: positions | + triangles |\n"
              "| --- | ---: | ---: | ---: | ---: |\n");
  for (const Scene& s : scenes) {
    auto tess = Tessellation::create(*s.evaluator, 2).value();
    DeformationResult r{1, s.mesh.positions()};
    std::printf("| %s | %zu B | %zu B | %zu B | %zu B |\n", s.name.c_str(), wire::encode_result_binary(r)->size(),
                wire::encode_result_json(r).size(), tess.vertices().size() * 12,
                tess.vertices().size() * 12 + tess.triangles().size() * 12);
  }

  // --- throughput ----------------------------------------------------------------------------------
  const Scene& spot = scenes[1];
  std::printf("\nthroughput on %s (binary, each client sends its next request when the last is answered):\n\n"
              "| clients | deformations | seconds | deformations/s | latency p50 | p95 |\n| ---: | ---: | ---: | ---: | ---: | ---: |\n",
              spot.name.c_str());
  for (const int clients : {1, 2, 8}) {
    const int each = std::max(5, 2 * solves / clients);
    std::vector<std::vector<double>> latency(static_cast<size_t>(clients));
    std::vector<std::thread> threads;
    const auto t0 = bench::Clock::now();
    for (int k = 0; k < clients; ++k) {
      threads.emplace_back([&, k] {
        std::mt19937 rng(100 + k);
        auto c = client(port);
        const std::string path = "/geometries/" + spot.id.hex() + "/results";
        for (int i = 0; i < each; ++i) {
          const auto t = bench::Clock::now();
          auto res = c->Post(path, headers(kBin), wire::encode_request_binary(grab(spot, rng)).value(), kBin);
          if (res && res->status == 200) {
            latency[static_cast<size_t>(k)].push_back(bench::ms_since(t));
          } else {
            std::fprintf(stderr, "client %d: %s\n", k, res ? res->body.c_str() : httplib::to_string(res.error()).c_str());
          }
        }
      });
    }
    for (auto& t : threads) t.join();
    const double seconds = bench::ms_since(t0) / 1000.0;
    std::vector<double> all;
    for (const auto& l : latency) all.insert(all.end(), l.begin(), l.end());
    std::printf("| %d | %zu | %.2f | %.0f | %.2f ms | %.2f ms |\n", clients, all.size(), seconds,
                static_cast<double>(all.size()) / seconds, bench::percentile(all, 0.5), bench::percentile(all, 0.95));
    std::fflush(stdout);
  }

  // --- long-poll wake-up ---------------------------------------------------------------------------
  const Scene& horse = scenes[0];
  constexpr int kWaiters = 20, kRounds = 20;
  std::vector<double> wake;
  std::mutex wake_mu;
  std::mt19937 rng(3);
  auto deformer = client(port);
  for (int round = 0; round < kRounds; ++round) {
    const uint32_t have = svc->info(horse.id).value().results;
    std::atomic<int> ready{0};
    std::vector<std::thread> waiters;
    for (int w = 0; w < kWaiters; ++w) {
      waiters.emplace_back([&] {
        auto c = client(port);
        ready.fetch_add(1);
        auto res = c->Get("/geometries/" + horse.id.hex() + "/latest_result?have=" + std::to_string(have) + "&wait=30",
                          headers(kBin));
        const auto now = std::chrono::system_clock::now();
        if (!res || res->status != 200) return;
        const auto r = wire::decode_result_binary(res->body).value();
        const auto stored = svc->result(horse.id, r.res_id).value()->stored_at;
        std::lock_guard lock(wake_mu);
        wake.push_back(std::chrono::duration<double, std::milli>(now - stored).count());
      });
    }
    while (ready.load() < kWaiters || server.waiting_long_polls() < kWaiters) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    deformer->Post("/geometries/" + horse.id.hex() + "/results", headers(kBin),
                   wire::encode_request_binary(grab(horse, rng)).value(), kBin);
    for (auto& t : waiters) t.join();
  }
  std::printf("\nlong-poll wake-up (result stored -> response decoded by the waiting client), %d waiters x %d "
              "results: p50 %.2f ms, p95 %.2f ms, max %.2f ms\n",
              kWaiters, kRounds, bench::percentile(wake, 0.5), bench::percentile(wake, 0.95),
              bench::percentile(wake, 1.0));
  server.stop();
  svc->shutdown();
  return 0;
}
