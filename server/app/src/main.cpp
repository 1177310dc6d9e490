// softshell-server: the simulation service of PROTOCOL.md over HTTP.
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <pthread.h>
#include <sys/resource.h>

// GCC 12 reports a potential null dereference inside CLI11's own string splitting
// (CLI::detail::split, inlined here) that cannot happen; it is silenced for this file only.
#pragma GCC diagnostic ignored "-Wnull-dereference"
#include <CLI/CLI.hpp>

#include "softshell/http/server.h"
#include "softshell/service/log.h"
#include "softshell/service/service.h"

namespace {

constexpr const char* kDescription =
    "Serves the softshell HTTP API (PROTOCOL.md): clients upload Catmull-Clark control meshes, the\n"
    "server precomputes their thin-shell stiffness and answers deformation requests; every client of a\n"
    "geometry shares its results.\n\n"
    "Every option can also come from its environment variable (shown as Env:), for containers; the\n"
    "command line wins. Options take their value as --opt value or --opt=value.\n";

constexpr const char* kFooter =
    "The server prints \"softshell-server listening on http://HOST:PORT\" once it accepts requests and\n"
    "stops cleanly on SIGINT or SIGTERM (waiting long polls and hold changes are answered, event\n"
    "streams end after the event they are sending, running solves finish).\n";

// What the command line sets (the defaults are the service's own where none is written here).
struct Options {
  std::string host = "127.0.0.1";
  int port = 8080;
  int threads = 0;
  int solve_threads = 0;
  int precompute_jobs = 1;
  size_t cache_mb = 0, store_mb = 0, max_body_mb = 0;
  int max_connections = 0;
  int event_writers = 0;
  size_t max_holds = 0;
  long long keep_results = -1, result_budget_mb = -1;  // -1: not given (the service's defaults)
  std::vector<std::string> cors_origins;
  std::string log_level = "info";
};

// Ranges are checked by CLI11; the help shows them in the text, so the validators stay unnamed.
CLI::Validator range(long long lo, long long hi) { return CLI::Range(lo, hi).description(""); }

void add_options(CLI::App& app, Options& o) {
  app.add_option("--host", o.host, "address to listen on (default 127.0.0.1; 0.0.0.0 for every\ninterface)")
      ->envname("SOFTSHELL_HOST")->type_name("HOST");
  app.add_option("--port", o.port, "TCP port, 0..65535 (default 8080; 0 picks a free port, printed\nat start)")
      ->envname("SOFTSHELL_PORT")->type_name("PORT")->check(range(0, 65535));
  app.add_option("--threads", o.threads, "threads of each precomputation, 1..4096 (default: the number\nof cores)")
      ->envname("SOFTSHELL_THREADS")->type_name("N")->check(range(1, 4096));
  app.add_option("--solve-threads", o.solve_threads, "solves running at once, 1..4096 (default: the number of\ncores)")
      ->envname("SOFTSHELL_SOLVE_THREADS")->type_name("N")->check(range(1, 4096));
  app.add_option("--precompute-jobs", o.precompute_jobs, "geometries precomputed at the same time, 1..256 (default 1)")
      ->envname("SOFTSHELL_PRECOMPUTE_JOBS")->type_name("N")->check(range(1, 256));
  app.add_option("--cache-mb", o.cache_mb,
                 "memory budget of the factorization cache in MiB (default 1024);\n"
                 "least recently used factors are evicted to stay under it")
      ->envname("SOFTSHELL_CACHE_MB")->type_name("MIB")->check(range(1, 1LL << 24));
  app.add_option("--store-mb", o.store_mb,
                 "memory budget in MiB for meshes, precomputed models, results,\n"
                 "holds and event-stream followers (default: half the physical\n"
                 "memory); an upload that does not fit is refused with 507; for a\n"
                 "result, the geometry's oldest results are dropped first")
      ->envname("SOFTSHELL_STORE_MB")->type_name("MIB")->check(range(1, 1LL << 26));
  app.add_option("--max-body-mb", o.max_body_mb, "largest request body in MiB, 1..4096 (default 64); larger\nbodies get 413")
      ->envname("SOFTSHELL_MAX_BODY_MB")->type_name("MIB")->check(range(1, 4096));
  app.add_option("--max-connections", o.max_connections,
                 "open connections served at once, one thread each, 8..32768\n"
                 "(default 1024); event streams (GET .../events) do not count: they\n"
                 "are served by the event writers and limited by the descriptor\n"
                 "limit and --store-mb")
      ->envname("SOFTSHELL_MAX_CONNECTIONS")->type_name("N")->check(range(8, 32768));
  app.add_option("--event-writers", o.event_writers,
                 "threads writing event streams, 1..64 (default: half the cores,\nat least 1)")
      ->envname("SOFTSHELL_EVENT_WRITERS")->type_name("N")->check(range(1, 64));
  app.add_option("--max-holds", o.max_holds,
                 "live holds one geometry takes at once, 1..65536 (default 256);\n"
                 "every hold-state solve combines all of them; a PUT that would\n"
                 "create one more gets 409")
      ->envname("SOFTSHELL_MAX_HOLDS")->type_name("N")->check(range(1, 65536));
  app.add_option("--keep-results", o.keep_results,
                 "results kept per geometry, the newest (default 1000; 0 = no\n"
                 "limit); an older one is 410 Gone, its id never reused")
      ->envname("SOFTSHELL_KEEP_RESULTS")->type_name("N")->check(range(0, 1LL << 31));
  app.add_option("--result-budget-mb", o.result_budget_mb,
                 "MiB of results kept per geometry, the newest (default 0 = no\n"
                 "limit but --keep-results and --store-mb)")
      ->envname("SOFTSHELL_RESULT_BUDGET_MB")->type_name("MIB")->check(range(0, 1LL << 26));
  app.add_option("--cors-origin", o.cors_origins,
                 "let pages from origin O (e.g. http://localhost:3000, or *) call\n"
                 "the API (CORS); repeatable; off by default")
      ->envname("SOFTSHELL_CORS_ORIGIN")->type_name("O")->allow_extra_args(false);
  app.add_option("--log-level", o.log_level,
                 "debug, info, warning, error or off (default info); info logs one\n"
                 "line per request: method, path, status, microseconds")
      ->envname("SOFTSHELL_LOG_LEVEL")->type_name("LEVEL")
      ->check(CLI::IsMember({"debug", "info", "warning", "error", "off"}, CLI::ignore_case).description(""));
}

// Parses the command line; returns the exit status when the program should stop now (help,
// version: 0; a bad option: 2, with the reason on stderr).
std::optional<int> parse(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::Success& e) {  // --help, --version
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "softshell-server: " << e.what() << "\n(see softshell-server --help)\n";
    return 2;
  }
  return std::nullopt;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace softshell;
  CLI::App app(kDescription, "softshell-server");
  app.footer(kFooter);
  app.set_version_flag("--version", std::string("softshell-server ") + SOFTSHELL_VERSION_STRING,
                       "print the version and exit");
  app.get_formatter()->column_width(34);
  Options o;
  add_options(app, o);
  if (auto stop = parse(app, argc, argv)) return *stop;

  service::ServiceOptions service_options;
  http::ServerOptions http_options;
  service_options.precompute_threads = o.threads;
  if (o.solve_threads > 0) service_options.solve_threads = o.solve_threads;
  service_options.precompute_jobs = o.precompute_jobs;
  if (o.cache_mb > 0) service_options.cache_bytes = o.cache_mb << 20;
  if (o.store_mb > 0) service_options.store_bytes = o.store_mb << 20;
  if (o.max_body_mb > 0) http_options.max_body_bytes = o.max_body_mb << 20;
  if (o.max_connections > 0) http_options.max_connections = o.max_connections;
  if (o.event_writers > 0) http_options.event_writers = o.event_writers;
  if (o.max_holds > 0) service_options.max_holds_per_geometry = o.max_holds;
  if (o.keep_results >= 0) service_options.retention.keep_results = static_cast<size_t>(o.keep_results);
  if (o.result_budget_mb >= 0) service_options.retention.bytes_per_geometry = static_cast<size_t>(o.result_budget_mb) << 20;
  http_options.cors_origins = o.cors_origins;
  const service::LogLevel level = service::parse_log_level(o.log_level).value();  // checked above

  const service::Logger logger{level, service::stderr_log_sink()};
  set_log_sink(logger.sink, level);  // the SDK's own reports (internal errors, failed assertions)
  service_options.logger = logger;
  http_options.logger = logger;
  http_options.reserved_connections = std::min(http_options.reserved_connections, http_options.max_connections / 2);

  // Every open connection and event stream is a descriptor: the soft limit (often 1024) is
  // raised to the hard one.
  rlimit files{};
  if (::getrlimit(RLIMIT_NOFILE, &files) == 0 && files.rlim_cur < files.rlim_max) {
    files.rlim_cur = files.rlim_max;
    ::setrlimit(RLIMIT_NOFILE, &files);
  }

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
  auto bound = server.start(o.host, o.port);
  if (!bound) {
    std::cerr << "softshell-server: " << bound.error().message << "\n";
    return 1;
  }
  const bool ipv6 = o.host.find(':') != std::string::npos;
  std::printf("softshell-server listening on http://%s%s%s:%d\n", ipv6 ? "[" : "", o.host.c_str(), ipv6 ? "]" : "",
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
