// The embedded server's C ABI entry points (softshell_embedded_c.h): an ss_session handle over an
// EmbeddedSession, under the SDK's C error policy (softshell_c_bridge.h).
#include "softshell/embedded_session.h"
#include "softshell/softshell_c_bridge.h"
#include "softshell/softshell_embedded_c.h"

#include <string>

using softshell::c_api::guard;

extern "C" {

SS_EMBEDDED_API void ss_embedded_options_default(ss_embedded_options* out) {
  if (!out) return;
  out->worker_threads = 0;
  out->cache_mb = 0;
  out->http_host = nullptr;
  out->http_port = 0;
}

SS_EMBEDDED_API ss_status ss_session_create_embedded(const ss_embedded_options* options, ss_session** out_session) {
  return guard("ss_session_create_embedded", [&] {
    if (!out_session) softshell::fail(softshell::ErrorCode::kInvalidArgument, "out_session is NULL");
    *out_session = nullptr;
    ss_embedded_options o;
    ss_embedded_options_default(&o);
    if (options) o = *options;
    if (o.worker_threads < 0 || o.cache_mb < 0 || o.http_port < 0 || o.http_port > 65535) {
      softshell::fail(softshell::ErrorCode::kInvalidArgument,
                      "worker_threads and cache_mb must be >= 0 and http_port in 0..65535");
    }
    softshell::service::ServiceOptions service_options;
    service_options.solve_threads = o.worker_threads;
    service_options.precompute_threads = o.worker_threads;
    if (o.cache_mb > 0) service_options.cache_bytes = static_cast<size_t>(o.cache_mb) << 20;
    auto session = std::make_shared<softshell::EmbeddedSession>(service_options);
    if (o.http_host) session->listen(o.http_host, o.http_port).value();
    *out_session = softshell::c_api::wrap_session(session);
  });
}

SS_EMBEDDED_API ss_status ss_session_embedded_port(const ss_session* session, int32_t* out_port) {
  return guard("ss_session_embedded_port", [&] {
    if (!out_port) softshell::fail(softshell::ErrorCode::kInvalidArgument, "out_port is NULL");
    auto embedded = std::dynamic_pointer_cast<softshell::EmbeddedSession>(softshell::c_api::session_of(session));
    if (!embedded) softshell::fail(softshell::ErrorCode::kInvalidArgument, "the session is not an embedded one");
    *out_port = embedded->port();
  });
}

}  // extern "C"
