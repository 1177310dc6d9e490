/* What a session keeps, through the C ABI from plain C11 on the in-process server
 * (softshell_embedded_c.h): deleting a geometry (ss_session_remove_geometry: its results are gone,
 * the id is unknown, an upload of the same content continues the result ids); a persistent
 * embedded server (ss_embedded_options.data_dir: what was stored is there after the session is
 * destroyed and created again); result retention (keep_results); requests still running when
 * the process exits are finished before it ends (their results are in the data directory). */

#define _XOPEN_SOURCE 700 /* mkdtemp */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "softshell/softshell_c.h"
#include "softshell/softshell_embedded_c.h"

#include "c_check.h"

enum { N = 4, NV = (N + 1) * (N + 1) };

/* On an n x n grid: the four corners pinned, a push down at the middle (scaled by k). */
static ss_request* pinned_push(int n, double k) {
  ss_request* request = NULL;
  CHECK_OK(ss_request_create(&request));
  const ss_vec3 zero = {0, 0, 0}, down = {0, 0, -0.25 * k};
  const int32_t corners[4] = {0, n, n * (n + 1), (n + 1) * (n + 1) - 1};
  for (int c = 0; c < 4; ++c) CHECK_OK(ss_request_add_vertex_constraint(request, corners[c], 7, &zero));
  CHECK_OK(ss_request_add_force(request, (n / 2) * (n + 1) + n / 2, &down));
  return request;
}

/* Deforms and returns the stored result's id (0 on failure). */
static uint32_t deform(ss_session* session, const ss_geom_id* id, double k) {
  ss_request* request = pinned_push(N, k);
  double xyz[3 * NV];
  uint32_t res_id = 0;
  int32_t count = 0;
  CHECK_OK(ss_session_deform(session, id, request, &res_id, xyz, NV, &count));
  CHECK(count == NV);
  ss_request_destroy(request);
  return res_id;
}

/* Uploads an n x n grid of the test's material (the mesh is released again). */
static ss_status upload_grid(ss_session* session, int n, ss_geom_id* id, int32_t* created) {
  ss_mesh* mesh = make_grid(n);
  const ss_material material = {7.0e10, 0.3, 0.01, 2700.0};
  const ss_status status = ss_session_upload(session, mesh, &material, NULL, id, created);
  ss_mesh_destroy(mesh);
  return status;
}

static void remove_geometry(void) {
  ss_session* session = NULL;
  CHECK_OK(ss_session_create_embedded(NULL, &session));
  ss_mesh* mesh = make_grid(N);
  const ss_material material = {7.0e10, 0.3, 0.01, 2700.0};
  ss_geom_id id;
  int32_t created = -1;
  CHECK_OK(ss_session_upload(session, mesh, &material, NULL, &id, &created));
  CHECK(created == 1);
  CHECK(deform(session, &id, 1.0) == 1);
  CHECK(deform(session, &id, 2.0) == 2);

  CHECK_OK(ss_session_remove_geometry(session, &id));
  ss_geometry_status status;
  CHECK_STATUS(ss_session_geometry_status(session, &id, &status, NULL, 0), SS_NOT_FOUND);
  int32_t has_new = -1, count = 0;
  uint32_t res_id = 0;
  double xyz[3 * NV];
  CHECK_STATUS(ss_session_latest_result(session, &id, 0, 0, &has_new, &res_id, xyz, NV, &count), SS_NOT_FOUND);
  CHECK_STATUS(ss_session_remove_geometry(session, &id), SS_NOT_FOUND);
  CHECK(strstr(ss_last_error_message(), "no geometry with id") != NULL);
  CHECK_STATUS(ss_session_remove_geometry(session, NULL), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_session_remove_geometry(NULL, &id), SS_INVALID_ARGUMENT);

  /* The same content again: a new geometry, whose ids continue after the deleted ones. */
  ss_geom_id again;
  CHECK_OK(ss_session_upload(session, mesh, &material, NULL, &again, &created));
  CHECK(created == 1 && memcmp(again.bytes, id.bytes, sizeof id.bytes) == 0);
  CHECK(deform(session, &id, 1.0) == 3);
  CHECK_OK(ss_session_latest_result(session, &id, 0, 0, &has_new, &res_id, xyz, NV, &count));
  CHECK(has_new == 1 && res_id == 3);
  ss_stress_field* field = NULL;
  CHECK_STATUS(ss_session_stresses(session, &id, 2, 1, NULL, 0, 0.0, &field), SS_GONE); /* the deleted upload's */
  CHECK(field == NULL);

  ss_mesh_destroy(mesh);
  ss_session_destroy(session);
}

/* The files a store directory holds (PersistentStore), removed with it. */
static void remove_store(const char* dir) {
  static const char* const kFiles[] = {"softshell.db", "softshell.db-wal", "softshell.db-shm", "softshell.lock"};
  char path[512];
  for (size_t k = 0; k < sizeof kFiles / sizeof kFiles[0]; ++k) {
    snprintf(path, sizeof path, "%s/%s", dir, kFiles[k]);
    remove(path);
  }
  CHECK(rmdir(dir) == 0);
}

/* Create with a data directory, post, destroy, create again: the results are there, bit for bit,
 * and the ids continue. */
static void persistent_session(void) {
  char dir[] = "/tmp/softshell-c-store-XXXXXX";
  if (mkdtemp(dir) == NULL) {
    CHECK(!"mkdtemp failed");
    return;
  }
  char data_dir[sizeof dir + 8];
  snprintf(data_dir, sizeof data_dir, "%s/store", dir); /* created by the server */
  ss_embedded_options options;
  ss_embedded_options_default(&options);
  CHECK(options.data_dir == NULL && options.keep_results == 0 && options.result_budget_mb == 0);
  options.data_dir = data_dir;

  ss_mesh* mesh = make_grid(N);
  const ss_material material = {7.0e10, 0.3, 0.01, 2700.0};
  ss_geom_id id;
  int32_t created = -1, count = 0, has_new = -1;
  uint32_t res_id = 0;
  double before[3 * NV], after[3 * NV];
  {
    ss_session* session = NULL;
    CHECK_OK(ss_session_create_embedded(&options, &session));
    /* One server per directory. */
    ss_session* second = NULL;
    CHECK_STATUS(ss_session_create_embedded(&options, &second), SS_UNAVAILABLE);
    CHECK(second == NULL && strstr(ss_last_error_message(), "in use by another softshell server") != NULL);
    CHECK_OK(ss_session_upload(session, mesh, &material, NULL, &id, &created));
    CHECK(created == 1);
    CHECK(deform(session, &id, 1.0) == 1);
    CHECK(deform(session, &id, 2.0) == 2);
    CHECK_OK(ss_session_latest_result(session, &id, 0, 0, &has_new, &res_id, before, NV, &count));
    CHECK(has_new == 1 && res_id == 2);
    ss_session_destroy(session);
  }
  ss_session* session = NULL;
  CHECK_OK(ss_session_create_embedded(&options, &session));
  ss_geometry_status status;
  CHECK_OK(ss_session_geometry_status(session, &id, &status, NULL, 0));
  CHECK(status.num_results == 2 && status.num_vertices == NV);
  CHECK_OK(ss_session_latest_result(session, &id, 0, 0, &has_new, &res_id, after, NV, &count));
  CHECK(has_new == 1 && res_id == 2 && count == NV && memcmp(before, after, sizeof before) == 0);
  CHECK_OK(ss_session_upload(session, mesh, &material, NULL, &id, &created));
  CHECK(created == 0); /* restored: not new */
  CHECK(deform(session, &id, 3.0) == 3);
  ss_session_destroy(session);

  /* A directory that cannot be one: a file. */
  char file[sizeof dir + 8];
  snprintf(file, sizeof file, "%s/file", dir);
  FILE* f = fopen(file, "w");
  CHECK(f != NULL);
  if (f) fclose(f);
  options.data_dir = file;
  CHECK_STATUS(ss_session_create_embedded(&options, &session), SS_INVALID_ARGUMENT);
  CHECK(session == NULL && strstr(ss_last_error_message(), "not a directory") != NULL);
  remove(file);

  ss_mesh_destroy(mesh);
  remove_store(data_dir);
  CHECK(rmdir(dir) == 0);
}

/* keep_results: the newest results stay, older ones are SS_GONE; bad values are refused. */
static void retention(void) {
  ss_embedded_options options;
  ss_embedded_options_default(&options);
  ss_session* session = NULL;
  options.keep_results = -2;
  CHECK_STATUS(ss_session_create_embedded(&options, &session), SS_INVALID_ARGUMENT);
  options.keep_results = 0;
  options.result_budget_mb = -1;
  CHECK_STATUS(ss_session_create_embedded(&options, &session), SS_INVALID_ARGUMENT);
  options.result_budget_mb = 0;
  options.keep_results = 2;
  CHECK_OK(ss_session_create_embedded(&options, &session));
  ss_geom_id id;
  int32_t created = -1;
  CHECK_OK(upload_grid(session, N, &id, &created));
  for (uint32_t k = 1; k <= 3; ++k) CHECK(deform(session, &id, (double)k) == k);
  ss_geometry_status status;
  CHECK_OK(ss_session_geometry_status(session, &id, &status, NULL, 0));
  CHECK(status.num_results == 2);
  ss_stress_field* field = NULL;
  CHECK_STATUS(ss_session_stresses(session, &id, 1, 1, NULL, 0, 0.0, &field), SS_GONE);
  CHECK(strstr(ss_last_error_message(), "no longer kept") != NULL);
  CHECK_OK(ss_session_stresses(session, &id, 2, 1, NULL, 0, 0.0, &field));
  ss_stress_field_destroy(field);
  ss_session_destroy(session);
}

enum { BIG_N = 40 };

/* The child process of requests_finish_at_exit: uploads a larger plate and begins two
 * deformations at once (they wait for the precomputation), destroys one operation and the session,
 * leaves the other handle live as a careless host would, and returns from main at once. */
static int exit_with_running_requests(const char* data_dir) {
  ss_embedded_options options;
  ss_embedded_options_default(&options);
  options.data_dir = data_dir;
  ss_session* session = NULL;
  if (ss_session_create_embedded(&options, &session) != SS_OK) return 2;
  ss_geom_id id;
  int32_t created = -1;
  if (upload_grid(session, BIG_N, &id, &created) != SS_OK) return 3;
  ss_request* request = pinned_push(BIG_N, 4.0);
  ss_deformation* destroyed = NULL;
  ss_deformation* left_live = NULL;
  if (ss_session_deform_begin(session, &id, request, &destroyed) != SS_OK) return 5;
  if (ss_session_deform_begin(session, &id, request, &left_live) != SS_OK) return 6;
  ss_geometry_status status;
  if (ss_session_geometry_status(session, &id, &status, NULL, 0) != SS_OK) return 7;
  ss_deformation_destroy(destroyed);
  ss_request_destroy(request);
  ss_session_destroy(session);
  if (status.status != SS_GEOMETRY_PRECOMPUTING) fprintf(stderr, "(precomputed before exit: a weaker test)\n");
  return 0;
}

/* Exit waits for running requests: both deformations of the child are stored in its data
 * directory, and the child exits normally (before, exit unloaded BLAS under a running solve). */
static void requests_finish_at_exit(const char* self) {
  char dir[] = "/tmp/softshell-c-exit-XXXXXX";
  if (mkdtemp(dir) == NULL) {
    CHECK(!"mkdtemp failed");
    return;
  }
  char data_dir[sizeof dir + 8];
  snprintf(data_dir, sizeof data_dir, "%s/store", dir);
  char command[1024];
  snprintf(command, sizeof command, "'%s' --exit-with-running-requests '%s'", self, data_dir);
  const int child = system(command);
  CHECK(child == 0);
  if (child != 0) fprintf(stderr, "requests_finish_at_exit: the child returned %d\n", child);

  ss_embedded_options options;
  ss_embedded_options_default(&options);
  options.data_dir = data_dir;
  ss_session* session = NULL;
  CHECK_OK(ss_session_create_embedded(&options, &session));
  ss_geom_id id;
  int32_t created = -1;
  CHECK_OK(upload_grid(session, BIG_N, &id, &created));
  CHECK(created == 0);
  ss_geometry_status status;
  CHECK_OK(ss_session_geometry_status(session, &id, &status, NULL, 0));
  CHECK(status.num_results == 2);
  ss_session_destroy(session);
  remove_store(data_dir);
  CHECK(rmdir(dir) == 0);
}

int main(int argc, char** argv) {
  if (argc == 3 && strcmp(argv[1], "--exit-with-running-requests") == 0) return exit_with_running_requests(argv[2]);
  remove_geometry();
  persistent_session();
  retention();
  requests_finish_at_exit(argv[0]);
  printf("c_api_store_test: %d checks, %d failures\n", g_checks, g_failures);
  return g_failures == 0 ? 0 : 1;
}
