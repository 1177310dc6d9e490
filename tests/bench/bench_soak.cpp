// Soak: a long session compressed in time. 4 clients post deformations of spot_quadrangulated
// (binary, over HTTP on 127.0.0.1, each sending its next request when its last one is answered)
// with the server's default retention (the newest 1,000 results per geometry). An hour of 4
// clients at 60 Hz is 864,000 requests; the default here is a smaller count (the table says how
// many ran and how long it took). Prints memory over time (the process's RSS, the service's
// budget in use, results kept and dropped) and fails if any request was not answered 200.
//
// usage: bench_soak [requests in total, default 40000] [clients, default 4]
// malloc is set up as softshell-server sets it; SOFTSHELL_BENCH_DEFAULT_MALLOC=1 leaves glibc's defaults.
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <random>
#include <thread>
#include <unistd.h>

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

double rss_mib() {
  std::ifstream statm("/proc/self/statm");
  size_t pages = 0, resident = 0;
  statm >> pages >> resident;
  return static_cast<double>(resident) * static_cast<double>(::sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0);
}

double mib(size_t bytes) { return static_cast<double>(bytes) / (1024.0 * 1024.0); }

}  // namespace

int main(int argc, char** argv) {
  const long total = argc > 1 ? std::atol(argv[1]) : 40000;
  const int clients = argc > 2 ? std::atoi(argv[2]) : 4;
  if (total <= 0 || clients <= 0) {
    std::fprintf(stderr, "usage: bench_soak [requests > 0] [clients > 0]\n");
    return 2;
  }
  bench::malloc_as_the_server();
  service::ServiceOptions options;  // the server's defaults: retention keeps the newest 1,000
  auto svc = std::make_shared<service::Service>(options);
  http::HttpServer server(svc);
  const int port = server.start("127.0.0.1", 0).value();

  ControlMesh mesh = test::load_asset_mesh("spot_quadrangulated.obj");
  const double scale = 1.0 / mesh.bounding_diagonal();
  for (Vec3& p : mesh.positions()) p *= scale;
  const Material material{6.9e10, 0.32, 0.002, 2700.0};
  const GeomId id = svc->upload(mesh, material).value().id;
  (void)svc->wait_until_precomputed(id, std::chrono::minutes(5)).value();
  // Supports: the lowest 5% of the control points (y up); the clients grab limit points elsewhere.
  std::vector<std::pair<double, int32_t>> by_height;
  for (int32_t i = 0; i < mesh.num_vertices(); ++i) by_height.push_back({mesh.positions()[static_cast<size_t>(i)].y(), i});
  std::sort(by_height.begin(), by_height.end());
  DeformationRequest supports;
  std::vector<char> held(by_height.size(), 0);
  for (size_t k = 0; k < by_height.size() / 20; ++k) {
    supports.vertex_constraints.push_back({by_height[k].second, kAxisAll, Vec3::Zero()});
    held[static_cast<size_t>(by_height[k].second)] = 1;
  }
  const LimitEvaluator evaluator = LimitEvaluator::create(mesh).value();
  std::vector<int32_t> free_faces;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    bool free = true;
    for (int32_t v : evaluator.support(f)) free = free && !held[static_cast<size_t>(v)];
    if (free) free_faces.push_back(f);
  }
  // A few hundred distinct bodies, reused (the requests differ; building them is not measured).
  std::vector<std::string> bodies;
  std::mt19937 rng(11);
  for (int i = 0; i < 256; ++i) {
    DeformationRequest r = supports;
    const SurfacePoint p{free_faces[rng() % free_faces.size()], 0, 0.5, 0.5};
    const LimitStencil st = evaluator.stencil(p);
    LagrangeConstraint c;
    c.indices = st.indices;
    for (double w : st.position) c.coefficients.push_back(Vec3(w, w, w));
    c.values = Vec3(0.0, 0.002 * (i % 7), 0.001 * (i % 5));
    r.lagrange_constraints.push_back(std::move(c));
    bodies.push_back(wire::encode_request_binary(r).value());
  }

  std::printf("softshell soak benchmark on %s: %d clients posting deformations of spot_quadrangulated (%d control "
              "points) over HTTP (binary, loopback), %ld requests, retention: newest %zu per geometry, store budget "
              "%.0f MiB\n\n",
              bench::machine().c_str(), clients, mesh.num_vertices(), total, options.retention.keep_results,
              mib(svc->stats().store_budget));
  std::printf("| requests answered | elapsed | simulated time at 4 x 60 Hz | RSS | store in use | results kept | "
              "results dropped | refused |\n| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  std::atomic<long> next{0}, ok{0}, failed{0};
  std::atomic<bool> done{false};
  const auto start = bench::Clock::now();
  auto row = [&] {
    const auto st = svc->stats();
    const long answered = ok.load() + failed.load();
    const double sim = static_cast<double>(answered) / (4.0 * 60.0);
    std::printf("| %ld | %.0f s | %02d:%02d | %.0f MiB | %.1f MiB | %llu | %llu | %llu |\n", answered,
                bench::ms_since(start) / 1000.0, static_cast<int>(sim) / 60, static_cast<int>(sim) % 60, rss_mib(),
                mib(st.store_bytes), static_cast<unsigned long long>(st.results),
                static_cast<unsigned long long>(st.results_dropped), static_cast<unsigned long long>(st.refused_no_memory));
    std::fflush(stdout);
  };
  row();
  std::vector<std::thread> threads;
  const std::string path = "/geometries/" + id.hex() + "/results";
  for (int t = 0; t < clients; ++t) {
    threads.emplace_back([&, t] {
      httplib::Client c("127.0.0.1", port);
      c.set_keep_alive(true);
      c.set_tcp_nodelay(true);
      c.set_read_timeout(120, 0);
      const httplib::Headers h{{"Accept", kBin}, {"Accept-Encoding", "identity"}};
      for (long k = next.fetch_add(1); k < total; k = next.fetch_add(1)) {
        auto res = c.Post(path, h, bodies[static_cast<size_t>(k + t) % bodies.size()], kBin);
        if (res && res->status == 200) {
          ok.fetch_add(1);
        } else {
          if (failed.fetch_add(1) < 5) {
            std::fprintf(stderr, "request %ld: %s\n", k, res ? (std::to_string(res->status) + " " + res->body).c_str()
                                                          : httplib::to_string(res.error()).c_str());
          }
        }
      }
    });
  }
  std::thread reporter([&] {
    const long step = std::max<long>(1, total / 20);
    long next_row = step;
    while (!done.load()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      if (ok.load() + failed.load() >= next_row) {
        row();
        next_row += step;
      }
    }
  });
  for (auto& t : threads) t.join();
  done.store(true);
  reporter.join();
  if ((ok.load() + failed.load()) % std::max<long>(1, total / 20) != 0) row();
  const double seconds = bench::ms_since(start) / 1000.0;
  std::printf("\n%ld requests in %.0f s (%.0f per second), %ld answered 200, %ld not.\n", total, seconds,
              static_cast<double>(total) / seconds, ok.load(), failed.load());
  server.stop();
  return failed.load() == 0 && ok.load() == total ? 0 : 1;
}
