// C ABI of the in-process server (softshell_embedded_c.h): an `ss_session` over an EmbeddedSession.

#include "softshell/softshell_embedded_c.h"

#include <memory>
#include <string>

#include "softshell/embedded_session.h"
#include "softshell/softshell_c_bridge.h"

extern "C" {

void ss_embedded_options_default(ss_embedded_options* out) {
  if (out) *out = ss_embedded_options{0, 0, nullptr, 0};
}

ss_status ss_session_create_embedded(const ss_embedded_options* options, ss_session** out_session) {
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
    if (o.http_host != nullptr && (o.http_port < 0 || o.http_port > 65535)) {
      softshell::fail(ErrorCode::kInvalidArgument, "http_port must be in 0..65535, got " + std::to_string(o.http_port));
    }
    softshell::service::ServiceOptions service;
    service.solve_threads = o.worker_threads;
    service.precompute_threads = o.worker_threads;
    if (o.cache_mb > 0) service.cache_bytes = static_cast<size_t>(o.cache_mb) << 20;
    auto session = std::make_shared<softshell::EmbeddedSession>(service);
    if (o.http_host != nullptr) session->listen(o.http_host, o.http_port).value();
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
