// C ABI of the in-process server (softshell_embedded_c.h): an `ss_session` over an EmbeddedSession.

#include "softshell/softshell_embedded_c.h"

#include <cstddef>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>
#include <type_traits>

#include "softshell/embedded_session.h"
#include "softshell/softshell_c_bridge.h"

extern "C" {

// The layout C# and other bindings rely on (an ABI break if it changes: bump SS_ABI_VERSION).
static_assert(offsetof(ss_embedded_options, http_host) == 16 && offsetof(ss_embedded_options, keep_results) == 80 &&
              offsetof(ss_embedded_options, result_budget_mb) == 84 && offsetof(ss_embedded_options, data_dir) == 88);
static_assert(sizeof(ss_embedded_options) == 88 + sizeof(void*));  // 96 on 64-bit, 92 on 32-bit platforms
static_assert(std::is_trivially_copyable_v<ss_embedded_options> && std::is_standard_layout_v<ss_embedded_options>);

static_assert(static_cast<int>(softshell::service::LogLevel::kDebug) == SS_LOG_DEBUG &&
              static_cast<int>(softshell::service::LogLevel::kError) == SS_LOG_ERROR);

namespace {

// The service's log messages go to the C log callback (ss_set_log_callback).
softshell::service::Logger c_logger() {
  softshell::service::Logger logger;
  logger.level = softshell::service::LogLevel::kDebug;  // the callback's threshold filters
  logger.sink = [](softshell::service::LogLevel level, std::string_view message) {
    softshell::c_api::log_message(static_cast<int32_t>(level), message);  // kDebug..kError = SS_LOG_*
  };
  return logger;
}

}  // namespace

void ss_embedded_options_default(ss_embedded_options* out) {
  if (out == nullptr) return;
  *out = ss_embedded_options{};
  std::memcpy(out->http_host, "127.0.0.1", sizeof("127.0.0.1"));
}

ss_status ss_session_create_embedded(const ss_embedded_options* options, ss_session** out_session) {
  return ss_session_create_embedded_on(options, nullptr, out_session);
}

ss_status ss_session_create_embedded_on(const ss_embedded_options* options, const ss_task_system* tasks,
                                        ss_session** out_session) {
  return softshell::c_api::guard("ss_session_create_embedded", [&] {
    using softshell::ErrorCode;
    if (out_session == nullptr) softshell::fail(ErrorCode::kInvalidArgument, "out_session is NULL");
    *out_session = nullptr;
    ss_embedded_options o;
    ss_embedded_options_default(&o);
    if (options) o = *options;
    if (o.worker_threads < 0 || o.worker_threads > 1024) {
      softshell::fail(ErrorCode::kInvalidArgument, "worker_threads must be in 0..1024 (0 = the number of cores)");
    }
    if (o.cache_mb < 0) softshell::fail(ErrorCode::kInvalidArgument, "cache_mb must not be negative");
    if (o.keep_results < -1) {
      softshell::fail(ErrorCode::kInvalidArgument, "keep_results must be -1 (no limit), 0 (the default: 1000) or a "
                                                   "count, got " + std::to_string(o.keep_results));
    }
    if (o.result_budget_mb < 0) {
      softshell::fail(ErrorCode::kInvalidArgument, "result_budget_mb must not be negative (0: no byte limit)");
    }
    std::string host;
    if (o.listen != 0) {
      const void* nul = std::memchr(o.http_host, '\0', sizeof(o.http_host));
      if (nul == nullptr) {
        softshell::fail(ErrorCode::kInvalidArgument,
                        "http_host is not NUL-terminated within its " + std::to_string(SS_HOST_CAPACITY) + " chars");
      }
      host = o.http_host;
      if (host.empty()) softshell::fail(ErrorCode::kInvalidArgument, "listen is set but http_host is empty");
      if (o.http_port < 0 || o.http_port > 65535) {
        softshell::fail(ErrorCode::kInvalidArgument, "http_port must be in 0..65535, got " + std::to_string(o.http_port));
      }
    }
    softshell::service::ServiceOptions service;
    service.solve_threads = o.worker_threads;
    service.precompute_threads = o.worker_threads;
    if (o.cache_mb > 0) service.cache_bytes = static_cast<size_t>(o.cache_mb) << 20;
    if (o.keep_results != 0) {
      service.retention.keep_results = o.keep_results > 0 ? static_cast<size_t>(o.keep_results) : 0;  // -1: none
    }
    service.retention.bytes_per_geometry = static_cast<size_t>(o.result_budget_mb) << 20;
    if (o.data_dir) service.data_dir = o.data_dir;
    service.logger = c_logger();
    if (tasks) service.executor = softshell::c_api::executor_of(*tasks);
    // Service::create: a data directory that cannot be used is an error status, not a throw.
    auto session = std::make_shared<softshell::EmbeddedSession>(softshell::service::Service::create(service).value());
    if (o.listen != 0) {
      softshell::http::ServerOptions http;
      http.logger = c_logger();
      session->listen(host, o.http_port, http).value();
    }
    *out_session = softshell::c_api::wrap_session(std::move(session));
  });
}

ss_status ss_session_embedded_port(const ss_session* session, int32_t* out_port) {
  return softshell::c_api::guard("ss_session_embedded_port", [&] {
    using softshell::ErrorCode;
    if (out_port == nullptr) softshell::fail(ErrorCode::kInvalidArgument, "out_port is NULL");
    auto embedded = std::dynamic_pointer_cast<softshell::EmbeddedSession>(softshell::c_api::session_of(session));
    if (!embedded) softshell::fail(ErrorCode::kInvalidArgument, "session is not an embedded session");
    *out_port = embedded->port();
  });
}

}  // extern "C"
