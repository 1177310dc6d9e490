/*
 * softshell C ABI, in-process server: creates an `ss_session` that runs the simulation server
 * inside the calling process (no sockets unless asked for). Everything else about sessions is in
 * softshell_c.h; the conventions there apply.
 *
 * Declared by the SDK, implemented by the embedded server library (softshell::embedded), so a
 * program that uses it links that library as well. Unity / Unreal: load the embedded library's
 * shared object; it exports these symbols next to the SDK's.
 */
#ifndef SOFTSHELL_EMBEDDED_C_H
#define SOFTSHELL_EMBEDDED_C_H

#include "softshell/softshell_c.h"

#if defined(_WIN32)
#  if defined(SOFTSHELL_EMBEDDED_BUILDING)
#    define SS_EMBEDDED_API __declspec(dllexport)
#  else
#    define SS_EMBEDDED_API __declspec(dllimport)
#  endif
#else
#  define SS_EMBEDDED_API __attribute__((visibility("default")))
#endif

#ifdef __cplusplus
extern "C" {
#endif

/** Options of the in-process server. */
typedef struct ss_embedded_options {
  int32_t worker_threads;  /* precomputation / solve threads; 0: the number of cores */
  int32_t cache_mb;        /* memory budget of cached factorizations in MiB; 0: the server default */
  const char* http_host;   /* NULL: no HTTP listener; else also serve PROTOCOL.md on this address */
  int32_t http_port;       /* port of the listener; 0: any free port */
} ss_embedded_options;

/** Writes the defaults (no listener, server defaults) into `*out` (no-op for NULL). */
SS_EMBEDDED_API void ss_embedded_options_default(ss_embedded_options* out);

/** Starts an in-process server and returns a session on it (`options` NULL: defaults). Destroy it
 *  with `ss_session_destroy`; the server stops when the session and its operations are gone. */
SS_EMBEDDED_API ss_status ss_session_create_embedded(const ss_embedded_options* options, ss_session** out_session);

/** The port of the session's HTTP listener, 0 if it has none. SS_INVALID_ARGUMENT for a session
 *  that is not an embedded one. */
SS_EMBEDDED_API ss_status ss_session_embedded_port(const ss_session* session, int32_t* out_port);

#ifdef __cplusplus
}  /* extern "C" */
#endif

#endif /* SOFTSHELL_EMBEDDED_C_H */
