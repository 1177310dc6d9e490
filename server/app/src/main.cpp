// softshell-server: the simulation service of PROTOCOL.md over HTTP.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <pthread.h>
#include <semaphore.h>
#include <sys/resource.h>

// GCC 12 reports a potential null dereference inside CLI11's own string splitting
// (CLI::detail::split, inlined here) that cannot happen; it is silenced for this file only.
#pragma GCC diagnostic ignored "-Wnull-dereference"
#include <CLI/CLI.hpp>

#include "softshell/http/auth.h"
#include "softshell/http/server.h"
#include "softshell/malloc_tuning.h"
#include "softshell/service/log.h"
#include "softshell/service/service.h"

namespace {

// The stop signal (SIGINT or SIGTERM), set by its handler, which posts g_stop (async-signal-safe).
volatile std::sig_atomic_t g_signal = 0;
sem_t g_stop;
void on_stop_signal(int number) {
  g_signal = number;
  sem_post(&g_stop);
}

constexpr const char* kDescription =
    "Serves the softshell HTTP API (PROTOCOL.md): clients upload Catmull-Clark control meshes, the\n"
    "server precomputes their thin-shell stiffness and answers deformation requests; every client of a\n"
    "geometry shares its results.\n\n"
    "Every option can also come from its environment variable (shown as Env:), for containers; the\n"
    "command line wins. Options take their value as --opt value or --opt=value.\n";

constexpr const char* kFooter =
    "The server prints \"softshell-server listening on http://HOST:PORT\" once it accepts requests and\n"
    "stops cleanly on SIGINT or SIGTERM: new requests and those waiting (long polls, hold changes,\n"
    "precomputations) are answered 503, running nonlinear solves and precomputations are cancelled,\n"
    "event streams end after the event they are sending and answers being sent finish, within\n"
    "--shutdown-timeout; then, or at a second signal, it exits at once (status 1).\n";

// What the command line sets (the defaults are the service's own where none is written here).
struct Options {
  std::string host = "127.0.0.1";
  int port = 8080;
  int threads = 0;
  int solve_threads = 0;
  int precompute_jobs = 1;
  size_t cache_mb = 0, store_mb = 0, max_body_mb = 0;
  int max_connections = 0;
  int max_connections_per_address = -1;  // -1: a quarter of --max-connections
  int event_writers = 0;
  size_t max_holds = 0;
  long long keep_results = -1, result_budget_mb = -1;  // -1: not given (the service's defaults)
  std::vector<std::string> cors_origins;
  std::string log_level = "info";
  double shutdown_timeout = 5.0;
  double nonlinear_time_limit = softshell::service::ServiceOptions{}.nonlinear.time_limit_seconds;  // its default
  std::string nonlinear_refresh = "counted";
  std::string auth_token_file;
  std::string data_dir;
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
                 "memory budget in MiB for meshes, precomputed models (linear and\n"
                 "nonlinear), results, holds and event-stream followers (default:\n"
                 "half the physical memory); an upload that does not fit is\n"
                 "refused with 507; for a result, the geometry's oldest results\n"
                 "are dropped first")
      ->envname("SOFTSHELL_STORE_MB")->type_name("MIB")->check(range(1, 1LL << 26));
  app.add_option("--max-body-mb", o.max_body_mb, "largest request body in MiB, 1..4096 (default 64); larger\nbodies get 413")
      ->envname("SOFTSHELL_MAX_BODY_MB")->type_name("MIB")->check(range(1, 4096));
  app.add_option("--max-connections", o.max_connections,
                 "open connections served at once, one thread each, 8..32768\n"
                 "(default 1024); event streams (GET .../events) do not count: they\n"
                 "are served by the event writers and limited by the descriptor\n"
                 "limit and --store-mb")
      ->envname("SOFTSHELL_MAX_CONNECTIONS")->type_name("N")->check(range(8, 32768));
  app.add_option("--max-connections-per-address", o.max_connections_per_address,
                 "connections one client address may have open at once, 0..32768\n"
                 "(default: a quarter of --max-connections; 0 = no limit, for a\n"
                 "proxy on the same host, where every client has its address);\n"
                 "beyond it a connection gets 503")
      ->envname("SOFTSHELL_MAX_CONNECTIONS_PER_ADDRESS")->type_name("N")->check(range(0, 32768));
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
  app.add_option("--nonlinear-time-limit", o.nonlinear_time_limit,
                 "seconds one nonlinear solve may take, 0..3600 (default 60; 0 = no\n"
                 "limit); one that has not converged by then is refused with 422")
      ->envname("SOFTSHELL_NONLINEAR_TIME_LIMIT")->type_name("S")->check(CLI::Range(0.0, 3600.0).description(""));
  app.add_option("--nonlinear-refresh", o.nonlinear_refresh,
                 "when nonlinear solves refactor their preconditioner: counted\n"
                 "(default; the same requests get the same answers bit for bit,\n"
                 "however busy the host) or timed (by measured costs; past a\n"
                 "buckling load answers can differ from run to run)")
      ->envname("SOFTSHELL_NONLINEAR_REFRESH")->type_name("RULE")
      ->check(CLI::IsMember({"counted", "timed"}).description(""));
  app.add_option("--shutdown-timeout", o.shutdown_timeout,
                 "seconds a stop may take to finish what is running, 0..3600\n"
                 "(default 5); then the server exits anyway")
      ->envname("SOFTSHELL_SHUTDOWN_TIMEOUT")->type_name("S")->check(CLI::Range(0.0, 3600.0).description(""));
  app.add_option("--log-level", o.log_level,
                 "debug, info, warning, error or off (default info); info logs one\n"
                 "line per request: method, path, status, microseconds")
      ->envname("SOFTSHELL_LOG_LEVEL")->type_name("LEVEL")
      ->check(CLI::IsMember({"debug", "info", "warning", "error", "off"}, CLI::ignore_case).description(""));
  app.add_option("--auth-token-file", o.auth_token_file,
                 "file holding an access token (16+ visible ASCII characters,\n"
                 "e.g. from `openssl rand -hex 32`): every request but GET /health\n"
                 "and the browser app's files then needs 'Authorization: Bearer\n"
                 "<token>' (401 otherwise); off by default")
      ->envname("SOFTSHELL_AUTH_TOKEN_FILE")->type_name("FILE");
  app.add_option("--data-dir", o.data_dir,
                 "keep geometries and results in DIR (created if missing; one\n"
                 "server per DIR) and restore them on start; every result is on\n"
                 "disk before it is answered; default: in memory only")
      ->envname("SOFTSHELL_DATA_DIR")->type_name("DIR");
}

// Seconds as a person writes them: 60, 0.5.
std::string format_seconds(double seconds) {
  std::ostringstream s;
  s << seconds;
  return s.str();
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
  service_options.nonlinear.time_limit_seconds = o.nonlinear_time_limit;
  service_options.nonlinear.reproducible = o.nonlinear_refresh == "counted";
  if (o.cache_mb > 0) service_options.cache_bytes = o.cache_mb << 20;
  if (o.store_mb > 0) service_options.store_bytes = o.store_mb << 20;
  if (o.max_body_mb > 0) http_options.max_body_bytes = o.max_body_mb << 20;
  if (o.max_connections > 0) http_options.max_connections = o.max_connections;
  if (o.event_writers > 0) http_options.event_writers = o.event_writers;
  http_options.max_connections_per_address =
      o.max_connections_per_address >= 0 ? o.max_connections_per_address : std::max(1, http_options.max_connections / 4);
  if (o.max_holds > 0) service_options.max_holds_per_geometry = o.max_holds;
  if (o.keep_results >= 0) service_options.retention.keep_results = static_cast<size_t>(o.keep_results);
  if (o.result_budget_mb >= 0) service_options.retention.bytes_per_geometry = static_cast<size_t>(o.result_budget_mb) << 20;
  http_options.cors_origins = o.cors_origins;
  std::vector<std::string> token_warnings;
  if (!o.auth_token_file.empty()) {
    auto token = http::read_auth_token_file(o.auth_token_file);
    if (!token) {
      std::cerr << "softshell-server: --auth-token-file: " << token.error().message << "\n";
      return 2;
    }
    http_options.auth_token = std::move(token->token);
    token_warnings = std::move(token->warnings);
  }
  const service::LogLevel level = service::parse_log_level(o.log_level).value();  // checked above

  const service::Logger logger{level, service::stderr_log_sink()};
  set_log_sink(logger.sink, level);  // the SDK's own reports (internal errors, failed assertions)
  service_options.logger = logger;
  http_options.logger = logger;
  for (const std::string& w : token_warnings) logger.warning(w);
  http_options.reserved_connections = std::min(http_options.reserved_connections, http_options.max_connections / 2);

  // Solves allocate buffers of megabytes again and again: freed memory is kept for the next one
  // instead of being faulted in anew (softshell/malloc_tuning.h).
  tune_malloc_for_solves();

  // Every open connection and event stream is a descriptor: the soft limit (often 1024) is
  // raised to the hard one.
  rlimit files{};
  if (::getrlimit(RLIMIT_NOFILE, &files) == 0 && files.rlim_cur < files.rlim_max) {
    files.rlim_cur = files.rlim_max;
    ::setrlimit(RLIMIT_NOFILE, &files);
  }

  // SIGINT and SIGTERM: every thread created from here on inherits the blocked mask, so no worker
  // is interrupted by them. Threads a library started before main (OpenBLAS's pool) do not block
  // them and may be the ones they are delivered to, so sigwait alone is not enough (the default
  // action would kill the process there): a handler that only records the signal takes them on
  // whichever thread, and the main thread unblocks them once the server runs.
  struct sigaction stop_action {};
  stop_action.sa_handler = on_stop_signal;
  stop_action.sa_flags = SA_RESTART;
  sigemptyset(&stop_action.sa_mask);
  sem_init(&g_stop, 0, 0);
  sigaction(SIGINT, &stop_action, nullptr);
  sigaction(SIGTERM, &stop_action, nullptr);
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  std::signal(SIGPIPE, SIG_IGN);

  service_options.data_dir = o.data_dir;
  auto created = service::Service::create(service_options);
  if (!created) {
    std::cerr << "softshell-server: " << created.error().message << "\n";
    return 1;
  }
  auto svc = std::move(*created);
  const engine::NonlinearOptions& nonlinear = service_options.nonlinear;
  logger.info(std::string("nonlinear solves: ") +
              (nonlinear.time_limit_seconds > 0.0 ? "at most " + format_seconds(nonlinear.time_limit_seconds) + " s each"
                                                  : "no time limit") +
              (nonlinear.reproducible ? ", refresh rule counted (reproducible answers)"
                                      : ", refresh rule timed (answers can differ from run to run past a buckling load)"));
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

  pthread_sigmask(SIG_UNBLOCK, &signals, nullptr);  // (the handler runs here or on a library's thread)
  while (sem_wait(&g_stop) != 0) {
  }
  const auto name = [](int sig) { return std::string(sig == SIGINT ? "SIGINT" : "SIGTERM"); };
  logger.info("received " + name(g_signal) + ", stopping (at most " + format_seconds(o.shutdown_timeout) +
              " s; a second signal stops at once)");
  // The service stops first: what waits for it is answered and long work is cancelled, so the
  // connections it held can finish. Then the HTTP server ends its connections and streams.
  std::atomic<bool> stopped{false};
  std::thread stopper([&] {
    svc->shutdown();
    server.stop();
    stopped.store(true);
  });
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(o.shutdown_timeout);
  while (!stopped.load()) {
    const bool again = sem_trywait(&g_stop) == 0;
    const bool late = std::chrono::steady_clock::now() >= deadline;
    if (again || late) {
      logger.error(std::string(again ? "received " + name(g_signal) + " again" : "the shutdown timeout passed") +
                   ": exiting with " + std::to_string(server.busy_connections()) + " connection(s) still busy");
      std::_Exit(1);  // what still runs is abandoned; every answer already sent stands
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  stopper.join();
  logger.info("stopped");
  return 0;
}
