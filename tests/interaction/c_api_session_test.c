/* A whole session through the C ABI from plain C11, on the in-process server
 * (softshell_embedded_c.h): upload, pick, grab, asynchronous deformation polled like a game loop,
 * reading the deformed control points, and errors reported by the server. */

#define _POSIX_C_SOURCE 199309L /* nanosleep */
#include <math.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "softshell/softshell_c.h"
#include "softshell/softshell_embedded_c.h"

#include "c_check.h"

/* The layout P/Invoke and other bindings see (bindings/csharp/Softshell.cs): fixed-size fields. */
_Static_assert(sizeof(ss_embedded_options) == 88 + sizeof(void*), "ss_embedded_options is 96 bytes (92 on 32-bit)");
_Static_assert(offsetof(ss_embedded_options, listen) == 8 && offsetof(ss_embedded_options, http_port) == 12 &&
                   offsetof(ss_embedded_options, http_host) == 16 &&
                   offsetof(ss_embedded_options, keep_results) == 80 &&
                   offsetof(ss_embedded_options, result_budget_mb) == 84 &&
                   offsetof(ss_embedded_options, data_dir) == 88,
               "ss_embedded_options field offsets");
_Static_assert(sizeof(ss_geometry_status) == 24 && offsetof(ss_geometry_status, progress) == 16,
               "ss_geometry_status layout");

enum { N = 6, NV = (N + 1) * (N + 1) };

/* A gently curved N x N plate over [0, 1]^2. */
static ss_mesh* make_plate(void) {
  double xyz[3 * NV];
  int32_t sizes[N * N], indices[4 * N * N];
  for (int j = 0; j <= N; ++j) {
    for (int i = 0; i <= N; ++i) {
      const double x = (double)i / N, y = (double)j / N;
      double* p = xyz + 3 * (j * (N + 1) + i);
      p[0] = x;
      p[1] = y;
      p[2] = 0.1 * x * (1.0 - x) + 0.05 * y * y;
    }
  }
  for (int j = 0; j < N; ++j) {
    for (int i = 0; i < N; ++i) {
      const int f = j * N + i;
      sizes[f] = 4;
      indices[4 * f + 0] = j * (N + 1) + i;
      indices[4 * f + 1] = j * (N + 1) + i + 1;
      indices[4 * f + 2] = (j + 1) * (N + 1) + i + 1;
      indices[4 * f + 3] = (j + 1) * (N + 1) + i;
    }
  }
  ss_mesh* mesh = NULL;
  CHECK_OK(ss_mesh_create(xyz, NV, sizes, N * N, indices, 4 * N * N, &mesh));
  return mesh;
}

/* The edge y = 0 clamped: the first two rows fixed on all axes. */
static void clamp(ss_request* request) {
  const ss_vec3 zero = {0, 0, 0};
  for (int j = 0; j < 2; ++j) {
    for (int i = 0; i <= N; ++i) CHECK_OK(ss_request_add_vertex_constraint(request, j * (N + 1) + i, 7, &zero));
  }
}

/* Log messages arrive on the server's threads. */
static atomic_int g_precompute_logs;
static void on_log(int32_t level, const char* message, void* user_data) {
  (void)user_data;
  if (level == SS_LOG_INFO && strstr(message, "precomputing geometry") != NULL) atomic_fetch_add(&g_precompute_logs, 1);
}

static void sleep_ms(int ms) {
  struct timespec t = {0, (long)ms * 1000000L};
  nanosleep(&t, NULL);
}

/* Polls like a game loop: a frame of work between polls, never blocking for long. */
static int wait_for(ss_deformation* op, int* out_polls) {
  int32_t ready = 0;
  int polls = 0;
  while (!ready && polls < 60000) {
    CHECK_OK(ss_deformation_poll(op, &ready));
    ++polls;
    if (!ready) CHECK_OK(ss_deformation_wait(op, 5, &ready)); /* stands in for a 5 ms frame */
  }
  *out_polls = polls;
  return ready;
}

int main(void) {
  CHECK_OK(ss_set_log_callback(on_log, NULL, SS_LOG_INFO));
  ss_embedded_options options;
  ss_embedded_options_default(&options);
  CHECK(options.listen == 0 && options.worker_threads == 0 && strcmp(options.http_host, "127.0.0.1") == 0);
  ss_session* session = NULL;
  CHECK_OK(ss_session_create_embedded(&options, &session));
  if (!session) {
    printf("c_api_session_test: %d checks, %d failures (no session)\n", g_checks, g_failures);
    return 1;
  }
  options.http_port = 70000;
  options.listen = 1;
  ss_session* bad = NULL;
  CHECK_STATUS(ss_session_create_embedded(&options, &bad), SS_INVALID_ARGUMENT);
  CHECK(bad == NULL);
  options.http_port = 0;
  memset(options.http_host, 'x', sizeof options.http_host); /* no NUL inside the field */
  CHECK_STATUS(ss_session_create_embedded(&options, &bad), SS_INVALID_ARGUMENT);
  CHECK(strstr(ss_last_error_message(), "NUL") != NULL);
  options.http_host[0] = '\0';
  CHECK_STATUS(ss_session_create_embedded(&options, &bad), SS_INVALID_ARGUMENT);
  CHECK(bad == NULL);

  /* Upload (idempotent). */
  ss_mesh* mesh = make_plate();
  const ss_material material = {7.0e10, 0.3, 0.01, 2700.0};
  ss_geom_id id;
  int32_t created = -1;
  CHECK_OK(ss_session_upload(session, mesh, &material, "c-test", &id, &created));
  CHECK(created == 1);
  ss_geom_id again;
  CHECK_OK(ss_session_upload(session, mesh, &material, "c-test", &again, &created));
  CHECK(created == 0 && memcmp(id.bytes, again.bytes, 16) == 0);
  const ss_material bad_material = {-1.0, 0.3, 0.01, 2700.0};
  CHECK_STATUS(ss_session_upload(session, mesh, &bad_material, NULL, &again, NULL), SS_UNPROCESSABLE);

  /* The precomputation, polled like a loading bar: progress in [0, 1], never going back. */
  ss_geometry_status status;
  char why[128] = "unset";
  double last_progress = 0.0;
  int monotone = 1, polls_until_ready = 0;
  do {
    CHECK_OK(ss_session_geometry_status(session, &id, &status, why, (int32_t)sizeof why));
    monotone = monotone && status.progress >= last_progress && status.progress <= 1.0;
    last_progress = status.progress;
    if (status.status == SS_GEOMETRY_PRECOMPUTING) sleep_ms(1);
  } while (status.status == SS_GEOMETRY_PRECOMPUTING && ++polls_until_ready < 30000);
  CHECK(monotone);
  CHECK(status.status == SS_GEOMETRY_READY && status.progress == 1.0 && why[0] == '\0');
  CHECK(status.num_vertices == NV && status.num_faces == N * N && status.num_results == 0);
  CHECK(atomic_load(&g_precompute_logs) == 1); /* the server's log reached the callback */
  ss_geom_id unknown_id;
  memset(&unknown_id, 3, sizeof unknown_id);
  CHECK_STATUS(ss_session_geometry_status(session, &unknown_id, &status, NULL, 0), SS_NOT_FOUND);
  CHECK_STATUS(ss_session_geometry_status(session, &id, NULL, NULL, 0), SS_INVALID_ARGUMENT);

  /* Pick with a ray from the hand. */
  ss_evaluator* ev = NULL;
  CHECK_OK(ss_evaluator_create(mesh, &ev));
  ss_tessellation* surface = NULL;
  CHECK_OK(ss_tessellation_create(ev, 3, &surface));
  ss_picker* picker = NULL;
  CHECK_OK(ss_picker_create(surface, &picker));
  const ss_pose hand = {{0.63, 0.81, 1.0}, {0, 0, 0, 1}};
  const ss_ray ray = {hand.position, {0.05, -0.1, -1.0}, 0.0, INFINITY};
  ss_pick pick;
  int32_t hit = 0;
  CHECK_OK(ss_picker_pick(picker, &ray, 1, &pick, &hit));
  CHECK(hit == 1 && pick.status == SS_REFINE_CONVERGED);

  /* The server's limit combination at the picked point is the local evaluator's stencil. */
  int32_t local_count = 0, server_count = 0;
  CHECK_OK(ss_evaluator_stencil(ev, &pick.point, NULL, NULL, NULL, NULL, 0, &local_count));
  CHECK_OK(ss_session_limit_comb(session, &id, &pick.point, NULL, NULL, NULL, NULL, 0, &server_count));
  CHECK(local_count == server_count && local_count >= 16 && local_count <= 64);
  if (local_count == server_count && local_count <= 64) {
    int32_t li[64], si[64];
    double lw[64], sw[64], sdu[64];
    CHECK_OK(ss_evaluator_stencil(ev, &pick.point, li, lw, NULL, NULL, 64, &local_count));
    CHECK_OK(ss_session_limit_comb(session, &id, &pick.point, si, sw, sdu, NULL, 64, &server_count));
    double worst = 0.0, sum = 0.0;
    for (int32_t k = 0; k < local_count; ++k) {
      CHECK(li[k] == si[k]);
      worst = fmax(worst, fabs(lw[k] - sw[k]));
      sum += sw[k];
    }
    CHECK(worst < 1e-12 && fabs(sum - 1.0) < 1e-12); /* and the weights form a partition of unity */
  }
  CHECK_STATUS(ss_session_limit_comb(session, &id, &pick.point, NULL, NULL, NULL, NULL, 1, &server_count),
               SS_INVALID_ARGUMENT);

  /* Grab it and lift the hand by 3 cm. */
  ss_grab* grab = NULL;
  CHECK_OK(ss_grab_begin(ev, &pick.point, NULL, 0, &hand, NULL, &grab));
  const ss_pose lifted = {{0.63, 0.81, 1.03}, {0, 0, 0, 1}};
  ss_vec3 target;
  CHECK_OK(ss_grab_target(grab, &lifted, &target));
  ss_request* request = NULL;
  CHECK_OK(ss_request_create(&request));
  clamp(request);
  CHECK_OK(ss_request_add_grab(request, grab, &lifted));

  /* Deform asynchronously; the game loop polls. */
  ss_deformation* op = NULL;
  CHECK_OK(ss_session_deform_begin(session, &id, request, &op));
  int polls = 0;
  CHECK(wait_for(op, &polls));
  uint32_t res_id = 0;
  int32_t count = 0;
  CHECK_OK(ss_deformation_read(op, &res_id, NULL, 0, &count));
  CHECK(count == NV);
  double deformed[3 * NV];
  CHECK_OK(ss_deformation_read(op, &res_id, deformed, NV, &count));
  CHECK(res_id == 1);
  ss_deformation_destroy(op);

  /* The deformed limit surface at the picked point is where the hand put it. */
  ss_limit_sample s;
  CHECK_OK(ss_evaluator_evaluate(ev, &pick.point, deformed, NV, &s));
  const double miss = sqrt((s.position.x - target.x) * (s.position.x - target.x) +
                           (s.position.y - target.y) * (s.position.y - target.y) +
                           (s.position.z - target.z) * (s.position.z - target.z));
  CHECK(miss < 1e-9);
  CHECK(fabs(target.z - pick.position.z - 0.03) < 1e-12);
  /* The clamped control points did not move. */
  double xyz[3 * NV];
  CHECK_OK(ss_mesh_positions(mesh, xyz, NV, &count));
  double clamp_motion = 0.0;
  for (int k = 0; k < 3 * 2 * (N + 1); ++k) clamp_motion = fmax(clamp_motion, fabs(deformed[k] - xyz[k]));
  CHECK(clamp_motion < 1e-12);

  /* The rendered surface and the picker follow the deformation. */
  CHECK_OK(ss_tessellation_update(surface, deformed, NV));
  CHECK_OK(ss_picker_refit(picker));
  ss_pick after;
  CHECK_OK(ss_picker_pick(picker, &ray, 1, &after, &hit));
  CHECK(hit == 1 && after.t < pick.t);

  /* Blocking deform, latest result. */
  CHECK_OK(ss_session_deform(session, &id, request, &res_id, deformed, NV, &count));
  CHECK(res_id == 2);
  int32_t has_new = 0;
  CHECK_OK(ss_session_latest_result(session, &id, 0, 0, &has_new, &res_id, deformed, NV, &count));
  CHECK(has_new == 1 && res_id == 2);
  CHECK_OK(ss_session_latest_result(session, &id, 2, 0, &has_new, &res_id, deformed, NV, &count));
  CHECK(has_new == 0);

  /* Stresses of result 2: at the level-1 tessellation's vertices, then at those samples' own
   * points (the same numbers both ways), a yield strength flagging or not, and bad queries. */
  ss_stress_field* field = NULL;
  CHECK_OK(ss_session_stresses(session, &id, 2, 1, NULL, 0, 1.0, &field));
  int32_t num_samples = 0;
  CHECK_OK(ss_stress_field_samples(field, NULL, 0, &num_samples));
  CHECK(num_samples == (2 * N + 1) * (2 * N + 1)); /* a level-1 tessellation of the N x N plate */
  ss_stress_sample* samples = (ss_stress_sample*)calloc((size_t)num_samples, sizeof(ss_stress_sample));
  ss_stress_sample* stress_again = (ss_stress_sample*)calloc((size_t)num_samples, sizeof(ss_stress_sample));
  ss_surface_point* where = (ss_surface_point*)calloc((size_t)num_samples, sizeof(ss_surface_point));
  CHECK(samples != NULL && stress_again != NULL && where != NULL);
  if (samples && stress_again && where) {
    CHECK_OK(ss_stress_field_samples(field, samples, num_samples, &count));
    CHECK_STATUS(ss_stress_field_samples(field, samples, num_samples - 1, &count), SS_BUFFER_TOO_SMALL);
    ss_stress_sample peak, peak_again;
    int32_t exceeds = -1;
    CHECK_OK(ss_stress_field_max(field, &peak, &exceeds));
    CHECK(exceeds == 1 && peak.von_mises_top > 1.0); /* 1 Pa: everything that bends yields */
    double largest = 0.0;
    for (int32_t k = 0; k < num_samples; ++k) {
      largest = fmax(largest, fmax(samples[k].von_mises_top, samples[k].von_mises_bottom));
      where[k] = samples[k].point;
    }
    CHECK(largest > 0.0);
    ss_stress_field* at_points = NULL;
    CHECK_OK(ss_session_stresses(session, &id, 2, 0, where, num_samples, 1e12, &at_points));
    CHECK_OK(ss_stress_field_samples(at_points, stress_again, num_samples, &count));
    CHECK(count == num_samples);
    double worst = 0.0;
    for (int32_t k = 0; k < num_samples; ++k) {
      worst = fmax(worst, fabs(stress_again[k].von_mises_top - samples[k].von_mises_top) / largest);
      worst = fmax(worst, fabs(stress_again[k].von_mises_bottom - samples[k].von_mises_bottom) / largest);
    }
    CHECK(worst < 1e-12);
    CHECK_OK(ss_stress_field_max(at_points, &peak_again, &exceeds));
    CHECK(exceeds == 0 && fabs(peak_again.von_mises_top - peak.von_mises_top) <= 1e-12 * peak.von_mises_top);
    ss_stress_field_destroy(at_points);
  }
  free(samples);
  free(stress_again);
  free(where);
  ss_stress_field* no_field = NULL;
  CHECK_STATUS(ss_session_stresses(session, &id, 2, 5, NULL, 0, 0.0, &no_field), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_session_stresses(session, &id, 2, 0, NULL, 0, 0.0, &no_field), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_session_stresses(session, &id, 2, 1, NULL, 0, NAN, &no_field), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_session_stresses(session, &id, 99, 1, NULL, 0, 0.0, &no_field), SS_NOT_FOUND);
  CHECK(no_field == NULL);
  ss_stress_field_destroy(field);
  ss_stress_sample unused;
  CHECK_STATUS(ss_stress_field_max(field, &unused, NULL), SS_INVALID_ARGUMENT); /* a destroyed handle */

  /* A request that leaves the plate free to move: the server's error comes back as a status. */
  ss_request* free_plate = NULL;
  CHECK_OK(ss_request_create(&free_plate));
  const ss_vec3 down = {0, 0, -10};
  CHECK_OK(ss_request_add_force(free_plate, 20, &down));
  CHECK_OK(ss_session_deform_begin(session, &id, free_plate, &op));
  CHECK(wait_for(op, &polls));
  CHECK_STATUS(ss_deformation_read(op, &res_id, deformed, NV, &count), SS_UNPROCESSABLE);
  CHECK(strlen(ss_last_error_message()) > 0);
  ss_deformation_destroy(op);
  /* An index the mesh does not have. */
  CHECK_OK(ss_request_add_force(free_plate, NV + 5, &down));
  CHECK_STATUS(ss_session_deform(session, &id, free_plate, &res_id, deformed, NV, &count), SS_INVALID_ARGUMENT);
  /* An unknown geometry. */
  ss_geom_id unknown;
  memset(&unknown, 7, sizeof unknown);
  CHECK_STATUS(ss_session_deform(session, &unknown, request, &res_id, deformed, NV, &count), SS_NOT_FOUND);

  /* The same through HTTP: a second in-process server with a listener, and a remote session. */
  ss_embedded_options listening;
  ss_embedded_options_default(&listening);
  listening.listen = 1;
  ss_session* host = NULL;
  CHECK_OK(ss_session_create_embedded(&listening, &host));
  int32_t port = 0;
  CHECK_OK(ss_session_embedded_port(host, &port));
  CHECK(port > 0);
  char url[64];
  snprintf(url, sizeof url, "http://127.0.0.1:%d", (int)port);
  ss_session* remote = NULL;
  CHECK_OK(ss_session_create_remote(url, NULL, &remote));
  if (remote) {
    CHECK_OK(ss_session_upload(remote, mesh, &material, "c-test", &again, &created));
    CHECK(created == 1 && memcmp(id.bytes, again.bytes, 16) == 0); /* same content, same id */
    CHECK_OK(ss_session_deform_begin(remote, &again, request, &op));
    CHECK(wait_for(op, &polls));
    CHECK_OK(ss_deformation_read(op, &res_id, deformed, NV, &count));
    ss_deformation_destroy(op);
    CHECK_OK(ss_evaluator_evaluate(ev, &pick.point, deformed, NV, &s));
    CHECK(fabs(s.position.x - target.x) + fabs(s.position.y - target.y) + fabs(s.position.z - target.z) < 1e-9);
  }
  ss_session_destroy(remote);
  ss_session_destroy(host);
  CHECK_STATUS(ss_session_embedded_port(session, NULL), SS_INVALID_ARGUMENT);
  ss_session* nowhere = NULL;
  ss_remote_options quick;
  ss_remote_options_default(&quick);
  quick.connect_timeout_ms = 500;
  snprintf(url, sizeof url, "http://127.0.0.1:%d", (int)port); /* the listener is closed now */
  CHECK_STATUS(ss_session_create_remote(url, &quick, &nowhere), SS_UNAVAILABLE);
  CHECK(nowhere == NULL);

  /* Releasing a running operation and the session never blocks. */
  CHECK_OK(ss_session_deform_begin(session, &id, request, &op));
  ss_deformation_destroy(op);

  ss_request_destroy(free_plate);
  ss_request_destroy(request);
  ss_grab_destroy(grab);
  ss_picker_destroy(picker);
  ss_tessellation_destroy(surface);
  ss_evaluator_destroy(ev);
  ss_mesh_destroy(mesh);
  ss_session_destroy(session);
  CHECK_OK(ss_set_log_callback(NULL, NULL, SS_LOG_OFF));
  printf("c_api_session_test: %d checks, %d failures\n", g_checks, g_failures);
  return g_failures == 0 ? 0 : 1;
}
