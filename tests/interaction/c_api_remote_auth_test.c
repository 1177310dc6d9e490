/* The C ABI's remote session against a softshell-server started with --auth-token-file (run by
 * c_api_remote_auth_test.sh, which starts the server): without ss_remote_options.auth_token, and
 * with a wrong one, every call but the connection's /health check is refused with the server's
 * message; with it (copied in at create) the session uploads and deforms.
 * Usage: c_api_remote_auth_test URL TOKEN */
#include <string.h>

#include "c_check.h"

enum { N = 4, NV = (N + 1) * (N + 1) };

int main(int argc, char** argv) {
  if (argc != 3) {
    fprintf(stderr, "usage: %s URL TOKEN\n", argv[0]);
    return 2;
  }
  const char* url = argv[1];
  ss_mesh* mesh = make_grid(N);
  ss_material material;
  ss_material_default(&material);
  ss_remote_options options;
  ss_remote_options_default(&options);
  CHECK(options.auth_token == NULL);
  ss_geom_id id;
  memset(&id, 0, sizeof id);

  /* No token, an empty one, a wrong one: refused (SS_INVALID_ARGUMENT), the message says why. */
  const char* refused[] = {NULL, "", "wrong-token-0123456789"};
  const char* says[] = {"Authorization: Bearer", "Authorization: Bearer", "not this server's"};
  for (int k = 0; k < 3; ++k) {
    options.auth_token = refused[k];
    ss_session* anonymous = NULL;
    CHECK_OK(ss_session_create_remote(url, &options, &anonymous)); /* /health needs no token */
    CHECK_STATUS(ss_session_upload(anonymous, mesh, &material, NULL, &id, NULL), SS_INVALID_ARGUMENT);
    CHECK(strstr(ss_last_error_message(), says[k]) != NULL);
    CHECK(strstr(ss_last_error_message(), "auth_token") != NULL);
    ss_session_destroy(anonymous);
  }

  /* The token, in a buffer the caller overwrites after create (the session keeps a copy). */
  char token[256];
  CHECK(strlen(argv[2]) < sizeof token);
  strncpy(token, argv[2], sizeof token - 1);
  token[sizeof token - 1] = '\0';
  options.auth_token = token;
  ss_session* session = NULL;
  CHECK_OK(ss_session_create_remote(url, &options, &session));
  memset(token, 'x', strlen(token));
  int32_t created = 0;
  CHECK_OK(ss_session_upload(session, mesh, &material, NULL, &id, &created));
  CHECK(created == 1);
  ss_request* request = NULL;
  CHECK_OK(ss_request_create(&request));
  const ss_vec3 zero = {0, 0, 0};
  const int32_t corners[4] = {0, N, N * (N + 1), NV - 1};
  for (int c = 0; c < 4; ++c) CHECK_OK(ss_request_add_vertex_constraint(request, corners[c], 7, &zero));
  const ss_vec3 push = {0, 0, -1.0};
  CHECK_OK(ss_request_add_force(request, (N / 2) * (N + 1) + N / 2, &push));
  uint32_t res_id = 0;
  double deformed[3 * NV];
  int32_t count = 0;
  CHECK_OK(ss_session_deform(session, &id, request, &res_id, deformed, NV, &count));
  CHECK(res_id == 1 && count == NV);
  CHECK(deformed[3 * ((N / 2) * (N + 1) + N / 2) + 2] < 0.0); /* the pushed point went down */
  ss_request_destroy(request);
  ss_session_destroy(session);
  ss_mesh_destroy(mesh);
  printf("c_api_remote_auth_test: %d checks, %d failures\n", g_checks, g_failures);
  return g_failures == 0 ? 0 : 1;
}
