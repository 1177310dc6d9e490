/*
 * softshell C ABI, in-process server: creates an `ss_session` that runs the simulation server
 * inside the calling process (no sockets unless asked for). Everything else about sessions is in
 * softshell_c.h; the conventions there apply.
 *
 * Implemented by the embedded server library (softshell::embedded), so a program that uses it
 * links that library as well. Unity / Unreal: load libsoftshell_plugin (softshell::plugin), the
 * one file with the whole C ABI, this part included.
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

/** Capacity of ss_embedded_options.http_host, the terminating NUL included. */
#define SS_HOST_CAPACITY 64

/** Options of the in-process server. Blittable: fixed-size plain fields and one pointer (96 bytes
 *  on 64-bit platforms, 92 on 32-bit; C# declares the host as `fixed byte http_host[64]` and
 *  data_dir as an IntPtr), so it crosses P/Invoke without marshalling. */
typedef struct ss_embedded_options {
  int32_t worker_threads;  /* precomputation / solve threads; 0: the number of cores */
  int32_t cache_mb;        /* memory budget of cached factorizations in MiB; 0: the server default */
  int32_t listen;          /* != 0: also serve PROTOCOL.md over HTTP on http_host:http_port */
  int32_t http_port;       /* port of the listener; 0: any free port (ss_session_embedded_port) */
  char http_host[SS_HOST_CAPACITY]; /* NUL-terminated address to listen on; default "127.0.0.1",
                                       "0.0.0.0" for every interface */
  int32_t keep_results;     /* results kept per geometry, the newest (older ones are SS_GONE); 0: the
                               server default (1000), -1: no count limit (softshell-server
                               --keep-results) */
  int32_t result_budget_mb; /* MiB of results kept per geometry; 0: no byte limit (the default;
                               --result-budget-mb) */
  const char* data_dir;     /* NUL-terminated directory of a persistent store (created if missing;
                               softshell-server --data-dir), copied in: geometries and results are
                               written there before they are answered, and a later session on the
                               same directory restores them. One session at a time holds a
                               directory (SS_UNAVAILABLE otherwise); a damaged or foreign store is
                               SS_INVALID_ARGUMENT, naming it. NULL or "": memory only (default) */
} ss_embedded_options;

/** Writes the defaults (no listener, server defaults, host "127.0.0.1", no data directory) into
 *  `*out` (no-op for NULL). */
SS_EMBEDDED_API void ss_embedded_options_default(ss_embedded_options* out);

/** Starts an in-process server and returns a session on it (`options` NULL: defaults). Destroy it
 *  with `ss_session_destroy`; the server stops when the session and its operations are gone. */
SS_EMBEDDED_API ss_status ss_session_create_embedded(const ss_embedded_options* options, ss_session** out_session);

/** The same, with the server's precomputations and solves run as the host's tasks (`tasks` NULL:
 *  the server's own threads): at most `worker_threads` solves and one precomputation at once,
 *  and the precomputation's parallel work, on `tasks->concurrency` threads. The host must keep
 *  running tasks until the session is destroyed (destroying it waits for the server's tasks). */
SS_EMBEDDED_API ss_status ss_session_create_embedded_on(const ss_embedded_options* options, const ss_task_system* tasks,
                                                        ss_session** out_session);

/** The port of the session's HTTP listener, 0 if it has none. SS_INVALID_ARGUMENT for a session
 *  that is not an embedded one. */
SS_EMBEDDED_API ss_status ss_session_embedded_port(const ss_session* session, int32_t* out_port);

#ifdef __cplusplus
}  /* extern "C" */
#endif

#endif /* SOFTSHELL_EMBEDDED_C_H */
