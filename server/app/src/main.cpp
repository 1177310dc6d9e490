// softshell-server: the simulation service of PROTOCOL.md over HTTP.
#include <csignal>
#include <charconv>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <string>
#include <thread>

#include <pthread.h>

#include "softshell/http/server.h"
#include "softshell/service/log.h"
#include "softshell/service/service.h"

namespace {

constexpr const char* kUsage = R"(usage: softshell-server [options]

Serves the softshell HTTP API (PROTOCOL.md): clients upload Catmull-Clark control meshes, the
server precomputes their thin-shell stiffness and answers deformation requests; every client of a
geometry shares its results.

options:
  --host HOST          address to listen on (default 127.0.0.1; 0.0.0.0 for every interface)
  --port PORT          TCP port (default 8080; 0 picks a free port, printed at start)
  --threads N          threads of each precomputation (default: the number of cores)
  --solve-threads N    solves running at once (default: the number of cores)
  --precompute-jobs N  geometries precomputed at the same time (default 1)
  --cache-mb M         memory budget of the factorization cache in MiB (default 1024);
                       least recently used factors are evicted to stay under it
  --store-mb S         memory budget in MiB for meshes, precomputed models and results
                       (default: half the physical memory); uploads and results that do not
                       fit are refused with 507, nothing stored is ever dropped
  --max-body-mb B      largest request body in MiB (default 64); larger bodies get 413
  --max-connections C  open connections served at once, one thread each (default 1024)
  --cors-origin O      let pages from origin O (e.g. http://localhost:3000, or *) call the API
                       (CORS); repeatable; off by default
  --log-level L        debug, info, warning, error or off (default info); info logs one line
                       per request: method, path, status, microseconds
  --help               this text

The server prints "softshell-server listening on http://HOST:PORT" once it accepts requests and
stops cleanly on SIGINT or SIGTERM (waiting long polls are answered, running solves finish).
)";

[[noreturn]] void usage_error(const std::string& message) {
  std::cerr << "softshell-server: " << message << "\n(see softshell-server --help)\n";
  std::exit(2);
}

long long integer_arg(const std::string& name, const std::string& text, long long lo, long long hi) {
  long long v = 0;
  auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (text.empty() || ec != std::errc() || ptr != text.data() + text.size() || v < lo || v > hi) {
    usage_error(name + " needs an integer in " + std::to_string(lo) + ".." + std::to_string(hi) + ", got '" + text + "'");
  }
  return v;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace softshell;
  std::string host = "127.0.0.1";
  int port = 8080;
  service::ServiceOptions service_options;
  http::ServerOptions http_options;
  service::LogLevel level = service::LogLevel::kInfo;
  int threads = 0;

  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) usage_error(arg + " needs a value");
      return argv[++i];
    };
    if (arg == "--help" || arg == "-h") {
      std::cout << kUsage;
      return 0;
    } else if (arg == "--host") {
      host = value();
    } else if (arg == "--port") {
      port = static_cast<int>(integer_arg(arg, value(), 0, 65535));
    } else if (arg == "--threads") {
      threads = static_cast<int>(integer_arg(arg, value(), 1, 4096));
    } else if (arg == "--solve-threads") {
      service_options.solve_threads = static_cast<int>(integer_arg(arg, value(), 1, 4096));
    } else if (arg == "--precompute-jobs") {
      service_options.precompute_jobs = static_cast<int>(integer_arg(arg, value(), 1, 256));
    } else if (arg == "--cache-mb") {
      service_options.cache_bytes = static_cast<size_t>(integer_arg(arg, value(), 1, 1 << 24)) << 20;
    } else if (arg == "--store-mb") {
      service_options.store_bytes = static_cast<size_t>(integer_arg(arg, value(), 1, 1 << 26)) << 20;
    } else if (arg == "--max-body-mb") {
      http_options.max_body_bytes = static_cast<size_t>(integer_arg(arg, value(), 1, 4096)) << 20;
    } else if (arg == "--max-connections") {
      http_options.max_connections = static_cast<int>(integer_arg(arg, value(), 8, 32768));
    } else if (arg == "--cors-origin") {
      http_options.cors_origins.push_back(value());
    } else if (arg == "--log-level") {
      auto parsed = service::parse_log_level(value());
      if (!parsed) usage_error(parsed.error().message);
      level = *parsed;
    } else {
      usage_error("unknown option '" + arg + "'");
    }
  }
  service_options.precompute_threads = threads;
  const service::Logger logger{level, service::stderr_log_sink()};
  set_log_sink(logger.sink, level);  // the SDK's own reports (internal errors, failed assertions)
  service_options.logger = logger;
  http_options.logger = logger;
  http_options.reserved_connections = std::min(http_options.reserved_connections, http_options.max_connections / 2);

  // SIGINT and SIGTERM are taken by sigwait below; every thread created from here on inherits
  // the blocked mask, so no worker is interrupted by them.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  std::signal(SIGPIPE, SIG_IGN);

  auto svc = std::make_shared<service::Service>(service_options);
  http::HttpServer server(svc, http_options);
  auto bound = server.start(host, port);
  if (!bound) {
    std::cerr << "softshell-server: " << bound.error().message << "\n";
    return 1;
  }
  const bool ipv6 = host.find(':') != std::string::npos;
  std::printf("softshell-server listening on http://%s%s%s:%d\n", ipv6 ? "[" : "", host.c_str(), ipv6 ? "]" : "",
              *bound);
  std::fflush(stdout);

  int received = 0;
  sigwait(&signals, &received);
  logger.info(std::string("received ") + (received == SIGINT ? "SIGINT" : "SIGTERM") + ", stopping");
  server.stop();
  svc->shutdown();
  logger.info("stopped");
  return 0;
}
