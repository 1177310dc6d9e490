// Fan-out benchmark of GET /geometries/{id}/events (README "Numbers", docs/api-notes.md):
// 100, 1,000 and 2,000 event subscribers on one server, each result's delivery lag (stored on
// the server -> complete event parsed by the subscriber) p50/p99/max, and the server's memory.
//
// Each run has a fresh server in a child process (its RSS is its own); the subscribers are non-blocking
// sockets read by one epoll thread in this process, on the same machine, so the two share the
// cores: the lag includes the subscribers' own reading. Store times come from a listener in the
// server process (Service::subscribe), written to shared memory with CLOCK_MONOTONIC.
//
// usage: bench_events [results per run, default 20] [rate Hz, default 10] [event writer threads, default 1]
#include <fcntl.h>
#include <sys/epoll.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/wait.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <mutex>
#include <thread>

#include "bench_support.h"
#include "softshell/http/server.h"
#include "softshell/service/service.h"
#include "softshell/wire.h"
#include "sse_client.h"  // connect_loopback
#include "test_meshes.h"

#include <httplib.h>  // last: its <resolv.h> defines a macro `_res` that breaks Eigen

using namespace softshell;

namespace {

constexpr int kMaxResults = 4096;
constexpr int kScenes = 2;

struct Shared {
  std::atomic<int> port{0};
  std::atomic<int> ready{0};
  char ids[kScenes][33] = {};
  std::atomic<int64_t> stored_ns[kScenes][kMaxResults] = {};
};

int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// User + system CPU seconds of a process so far.
// The whole of a small /proc file.
std::string proc_file(pid_t pid, const char* name) {
  const std::string path = "/proc/" + std::to_string(pid) + "/" + name;
  std::string text;
  if (FILE* f = std::fopen(path.c_str(), "r")) {
    char buf[4096];
    size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) text.append(buf, n);
    std::fclose(f);
  }
  return text;
}

double cpu_seconds(pid_t pid) {
  const std::string text = proc_file(pid, "stat");
  // Fields after the command's closing parenthesis: 3 = state, ..., 14 = utime, 15 = stime.
  size_t pos = text.rfind(')') + 2;
  double utime = 0, stime = 0;
  for (int field = 3; field <= 15 && pos < text.size(); ++field) {
    const size_t end = text.find(' ', pos);
    if (field == 14) utime = std::atof(text.c_str() + pos);
    if (field == 15) stime = std::atof(text.c_str() + pos);
    pos = end == std::string::npos ? text.size() : end + 1;
  }
  return (utime + stime) / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

double rss_mib(pid_t pid) {
  const std::string text = proc_file(pid, "status");
  const size_t at = text.find("VmRSS:");
  return at == std::string::npos ? 0.0 : std::atof(text.c_str() + at + 6) / 1024.0;
}

ControlMesh scene_mesh(int k) {
  if (k == 0) return test::make_grid(8, 8);  // 81 control points: ~4 KB events
  ControlMesh m = test::load_asset_mesh("catmark_righthanded.obj");  // 436 control points: ~28 KB events
  const double scale = 1.0 / m.bounding_diagonal();
  for (Vec3& p : m.positions()) p *= scale;
  return m;
}

DeformationRequest scene_request(int scene, const ControlMesh& mesh, int k) {
  if (scene == 0) {  // the grid: corners held, a force in the middle
    DeformationRequest r;
    for (int j : {0, 8}) {
      for (int i : {0, 8}) r.vertex_constraints.push_back({test::grid_index(8, i, j), kAxisAll, Vec3::Zero()});
    }
    r.forces.push_back({test::grid_index(8, 4, 4), Vec3(0.0, 0.0, -1e-3 * (1 + k % 7))});
    return r;
  }
  // The lowest 5% of the control points held, a force on the highest.
  std::vector<std::pair<double, int32_t>> by_height;
  for (int32_t i = 0; i < mesh.num_vertices(); ++i) by_height.push_back({mesh.positions()[i].y() + mesh.positions()[i].z(), i});
  std::sort(by_height.begin(), by_height.end());
  DeformationRequest r;
  for (size_t i = 0; i < std::max<size_t>(4, by_height.size() / 20); ++i) {
    r.vertex_constraints.push_back({by_height[i].second, kAxisAll, Vec3::Zero()});
  }
  r.forces.push_back({by_height.back().second, Vec3(0.0, 0.0, -1e-3 * (1 + k % 7))});
  return r;
}

// The server process: serves until `release` is closed by the parent.
[[noreturn]] void serve(Shared* shared, int release, int writers, int scene) {
  service::ServiceOptions so;
  so.precompute_threads = 2;
  auto svc = std::make_shared<service::Service>(so);
  http::ServerOptions ho;
  ho.logger = {};
  ho.event_writers = writers;
  http::HttpServer server(svc, ho);
  const int port = server.start("127.0.0.1", 0).value();
  std::vector<std::unique_ptr<service::Subscription>> stamps;
  for (int k = scene; k == scene; ++k) {
    const Material material{6.9e10, 0.32, 0.002, 2700.0};
    const auto up = svc->upload(scene_mesh(k), material).value();
    (void)svc->wait_until_precomputed(up.id, std::chrono::minutes(5));
    std::snprintf(shared->ids[k], sizeof shared->ids[k], "%s", up.id.hex().c_str());
    stamps.push_back(svc->subscribe(up.id, [shared, k](const service::ResultPtr& r) {
      if (r->res_id < kMaxResults) shared->stored_ns[k][r->res_id].store(now_ns());
    }).value());
  }
  shared->port.store(port);
  shared->ready.store(1);
  char byte;
  while (::read(release, &byte, 1) > 0) {
  }
  stamps.clear();
  server.stop();
  svc->shutdown();
  std::_Exit(0);
}

// A subscriber's bytes: the head, then chunks that each hold one complete event (the server
// frames every event as one chunk), so an event is complete at "\n\n\r\n". Lighter than
// test::SseParser, whose copies would otherwise dominate the reading thread.
struct Subscriber {
  int fd = -1;
  std::string buffer;
  bool head = false;
  std::atomic<uint32_t> last{0};
  size_t event_bytes = 0;

  // Appends bytes and returns the ids of the events they complete.
  void feed(const char* data, size_t n, std::vector<uint32_t>& ids) {
    buffer.append(data, n);
    size_t pos = 0;
    if (!head) {
      const size_t end = buffer.find("\r\n\r\n");
      if (end == std::string::npos) return;
      head = true;
      pos = end + 4;
    }
    for (;;) {
      const size_t end = buffer.find("\n\n\r\n", pos);
      if (end == std::string::npos) break;
      const size_t id = buffer.find("id: ", pos);
      if (id != std::string::npos && id < end) {
        ids.push_back(static_cast<uint32_t>(std::strtoul(buffer.c_str() + id + 4, nullptr, 10)));
        event_bytes = end + 2 - id;
      }
      pos = end + 4;
    }
    buffer.erase(0, pos);
  }
};

struct RunResult {
  std::vector<double> lags_ms;
  size_t missed = 0;
  size_t frame_bytes = 0;
  double rss_before = 0, rss_with = 0;
  double connect_s = 0;
  double server_cpu_ms = 0;  // per result, while fanning out
  // The server's own delivery lag (result reaching the writers -> event written to the socket,
  // softshell_http_event_delivery_seconds): share of events within 10 ms and within 50 ms.
  double server_within_10 = 0, server_within_50 = 0;
};

// The share of a Prometheus histogram's samples at or below `le` (a bucket bound).
double share_within(const std::string& metrics, const std::string& name, const char* le) {
  auto value = [&](const std::string& key) {
    const size_t at = metrics.find(key);
    return at == std::string::npos ? 0.0 : std::atof(metrics.c_str() + at + key.size());
  };
  const double count = value(name + "_count ");
  return count > 0 ? value(name + "_bucket{le=\"" + le + "\"} ") / count : 0.0;
}

RunResult run(Shared* shared, pid_t server, int scene, int subscribers, int results, double hz) {
  RunResult out;
  const int port = shared->port.load();
  const std::string id = shared->ids[scene];
  auto producer = std::make_unique<httplib::Client>("127.0.0.1", port);
  producer->set_keep_alive(true);
  producer->set_tcp_nodelay(true);
  producer->set_read_timeout(60, 0);
  auto post = [&](int k) {
    const ControlMesh mesh = scene_mesh(scene);
    auto r = producer->Post(("/geometries/" + id + "/results").c_str(), {{"Accept", "application/octet-stream"}},
                            wire::encode_request_binary(scene_request(scene, mesh, k)).value(), "application/octet-stream");
    if (!r || r->status != 200) {
      std::fprintf(stderr, "POST failed: %s\n", r ? (std::to_string(r->status) + " " + r->body).c_str() : httplib::to_string(r.error()).c_str());
      return 0u;
    }
    return wire::decode_result_binary(r->body).value().res_id;
  };
  const uint32_t base = post(0);  // every subscriber gets this one at once: it shows it is connected
  out.rss_before = rss_mib(server);

  const int ep = ::epoll_create1(0);
  std::vector<Subscriber> subs(static_cast<size_t>(subscribers));
  const auto t0 = bench::Clock::now();
  for (int i = 0; i < subscribers; ++i) {
    Subscriber& s = subs[static_cast<size_t>(i)];
    s.fd = test::connect_loopback(port);
    if (s.fd < 0) {
      std::fprintf(stderr, "connect %d failed\n", i);
      std::exit(1);
    }
    const std::string req = "GET /geometries/" + id + "/events HTTP/1.1\r\nHost: 127.0.0.1\r\nAccept: text/event-stream\r\n\r\n";
    (void)!::send(s.fd, req.data(), req.size(), MSG_NOSIGNAL);
    ::fcntl(s.fd, F_SETFL, ::fcntl(s.fd, F_GETFL) | O_NONBLOCK);
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.u32 = static_cast<uint32_t>(i);
    ::epoll_ctl(ep, EPOLL_CTL_ADD, s.fd, &ev);
  }

  // The reader: records the lag of every complete event.
  std::atomic<bool> stop{false};
  std::vector<std::vector<double>> per_result(static_cast<size_t>(kMaxResults));
  std::atomic<int> got_base{0};
  std::mutex mu;
  std::thread reader([&] {
    std::vector<epoll_event> events(1024);
    std::vector<char> buf(1 << 16);
    std::vector<uint32_t> ids;
    while (!stop.load()) {
      const int n = ::epoll_wait(ep, events.data(), static_cast<int>(events.size()), 50);
      for (int e = 0; e < n; ++e) {
        Subscriber& s = subs[events[static_cast<size_t>(e)].data.u32];
        ids.clear();
        for (;;) {
          const ssize_t got = ::recv(s.fd, buf.data(), buf.size(), 0);
          if (got <= 0) break;
          s.feed(buf.data(), static_cast<size_t>(got), ids);
        }
        const int64_t t = now_ns();
        for (uint32_t rid : ids) {
          s.last.store(rid);
          if (rid == base) {
            got_base.fetch_add(1);
            out.frame_bytes = s.event_bytes;
            continue;
          }
          const int64_t stored = shared->stored_ns[scene][rid].load();
          std::lock_guard lock(mu);
          per_result[rid].push_back(static_cast<double>(t - stored) * 1e-6);
        }
      }
    }
  });
  while (got_base.load() < subscribers && bench::ms_since(t0) < 60000) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  out.connect_s = bench::ms_since(t0) / 1000.0;
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  out.rss_with = rss_mib(server);

  std::vector<uint32_t> produced;
  const double cpu0 = cpu_seconds(server);
  const auto period = std::chrono::duration<double>(1.0 / hz);
  auto next = bench::Clock::now();
  for (int k = 1; k <= results; ++k) {
    next += std::chrono::duration_cast<bench::Clock::duration>(period);
    std::this_thread::sleep_until(next);
    produced.push_back(post(k));
  }
  // Wait for every subscriber to reach the last one.
  const auto deadline = bench::Clock::now() + std::chrono::seconds(10);
  for (;;) {
    bool all = true;
    for (const auto& s : subs) all = all && s.last.load() >= produced.back();
    if (all || bench::Clock::now() > deadline) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  out.server_cpu_ms = (cpu_seconds(server) - cpu0) * 1e3 / results;
  stop.store(true);
  reader.join();
  if (auto m = producer->Get("/metrics"); m && m->status == 200) {
    out.server_within_10 = share_within(m->body, "softshell_http_event_delivery_seconds", "0.01");
    out.server_within_50 = share_within(m->body, "softshell_http_event_delivery_seconds", "0.05");
  }
  for (uint32_t rid : produced) {
    out.lags_ms.insert(out.lags_ms.end(), per_result[rid].begin(), per_result[rid].end());
    out.missed += static_cast<size_t>(subscribers) - per_result[rid].size();
  }
  for (auto& s : subs) ::close(s.fd);
  ::close(ep);
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  const int results = argc > 1 ? std::atoi(argv[1]) : 20;
  const double hz = argc > 2 ? std::atof(argv[2]) : 10.0;
  const int writers = argc > 3 ? std::atoi(argv[3]) : 1;
  rlimit lim{};
  ::getrlimit(RLIMIT_NOFILE, &lim);
  lim.rlim_cur = lim.rlim_max;
  ::setrlimit(RLIMIT_NOFILE, &lim);

  auto* shared = static_cast<Shared*>(::mmap(nullptr, sizeof(Shared), PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0));
  double load[3] = {0, 0, 0};
  (void)!::getloadavg(load, 3);
  std::printf("softshell event fan-out on %s (load average %.1f when started); a fresh server process per run, "
              "subscribers in one epoll thread of another process, %d results at %.0f Hz per run, %d event writer "
              "threads (descriptor limit %llu)\n\n",
              bench::machine().c_str(), load[0], results, hz, writers, static_cast<unsigned long long>(lim.rlim_cur));
  std::printf("| mesh | event bytes | subscribers | connect all | lag p50 | p99 | max | missed | server: written within 10 ms | 50 ms | "
              "server CPU per result | server RSS idle | with subscribers | per subscriber |\n| --- | ---: | ---: | ---: | "
              "---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  for (int scene = 0; scene < kScenes; ++scene) {
    for (int n : {100, 1000, 2000}) {
      new (shared) Shared();
      int pipe_fds[2];
      if (::pipe(pipe_fds) != 0) return 1;
      const pid_t child = ::fork();  // (this process runs no other thread here)
      if (child == 0) {
        ::close(pipe_fds[1]);
        serve(shared, pipe_fds[0], writers, scene);
      }
      ::close(pipe_fds[0]);
      while (!shared->ready.load()) std::this_thread::sleep_for(std::chrono::milliseconds(10));
      const RunResult r = run(shared, child, scene, n, results, hz);
      std::printf("| %s | %zu | %d | %.2f s | %.2f ms | %.2f ms | %.2f ms | %zu | %.1f%% | %.1f%% | %.1f ms | %.1f MiB | %.1f MiB | %.1f KiB |\n",
                  scene == 0 ? "grid 8x8" : "catmark_righthanded", r.frame_bytes, n, r.connect_s,
                  bench::percentile(r.lags_ms, 0.5), bench::percentile(r.lags_ms, 0.99),
                  r.lags_ms.empty() ? 0.0 : *std::max_element(r.lags_ms.begin(), r.lags_ms.end()), r.missed,
                  100.0 * r.server_within_10, 100.0 * r.server_within_50, r.server_cpu_ms, r.rss_before, r.rss_with, (r.rss_with - r.rss_before) * 1024.0 / n);
      std::fflush(stdout);
      ::close(pipe_fds[1]);
      int status = 0;
      ::waitpid(child, &status, 0);
    }
  }
  return 0;
}
