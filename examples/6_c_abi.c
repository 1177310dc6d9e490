/* Example 6: the C ABI, from plain C, against the one-file plug-in library (libsoftshell_plugin,
 * what Unity's Assets/Plugins or Unreal's ThirdParty holds), in the steps an engine plug-in takes:
 * start the in-process server, upload a plate, show the precomputation's progress, deform without
 * blocking (one poll per frame) and read the deformed control points. The plate is simply
 * supported and pressed at its centre with 100 N; its centre deflection is compared with Kirchhoff
 * plate theory (w = 0.01160 P a^2 / D, Timoshenko & Woinowsky-Krieger). */
#define _POSIX_C_SOURCE 199309L /* nanosleep */
#include <math.h>
#include <stdio.h>
#include <time.h>

#include "softshell/softshell_c.h"
#include "softshell/softshell_embedded_c.h"

enum { N = 16, NV = (N + 1) * (N + 1) };

/* Every call returns a status; ss_last_error_message() says what went wrong. */
#define TRY(call)                                                                                            \
  do {                                                                                                       \
    const ss_status s_ = (call);                                                                             \
    if (s_ != SS_OK) return fprintf(stderr, "%s: %s: %s\n", #call, ss_status_name(s_), ss_last_error_message()), 1; \
  } while (0)

static void frame(void) { /* the rest of a 5 ms game frame */
  const struct timespec t = {0, 5000000L};
  nanosleep(&t, NULL);
}

int main(void) {
  if (ss_abi_version() != SS_ABI_VERSION) return fprintf(stderr, "a library of another ABI\n"), 1;
  static double xyz[3 * NV], deformed[3 * NV];
  static int32_t sizes[N * N], corners[4 * N * N];
  for (int k = 0; k < NV; ++k) xyz[3 * k] = (double)(k % (N + 1)) / N, xyz[3 * k + 1] = (double)(k / (N + 1)) / N;
  for (int f = 0; f < N * N; ++f) { /* quads counter-clockwise seen from +z */
    int32_t* c = corners + 4 * f;
    sizes[f] = 4;
    c[0] = f / N * (N + 1) + f % N, c[1] = c[0] + 1, c[2] = c[0] + N + 2, c[3] = c[0] + N + 1;
  }
  ss_mesh* mesh = NULL;
  TRY(ss_mesh_create(xyz, NV, sizes, N * N, corners, 4 * N * N, &mesh));

  ss_embedded_options options;
  ss_embedded_options_default(&options); /* all cores, no HTTP listener */
  ss_session* session = NULL;
  TRY(ss_session_create_embedded(&options, &session));
  ss_material steel;
  TRY(ss_material_preset("steel", 0.005, &steel)); /* 5 mm */
  ss_geom_id id;
  TRY(ss_session_upload(session, mesh, &steel, NULL, &id, NULL));

  ss_geometry_status geometry; /* a loading bar while the server precomputes the stiffness */
  char why[256];
  double shown = -1.0;
  printf("softshell %s precomputing:", ss_version());
  do {
    TRY(ss_session_geometry_status(session, &id, &geometry, why, sizeof why));
    if (geometry.progress != shown) printf(" %.0f%%", 100.0 * (shown = geometry.progress));
    if (geometry.status == SS_GEOMETRY_PRECOMPUTING) frame();
  } while (geometry.status == SS_GEOMETRY_PRECOMPUTING);
  printf("\n");
  if (geometry.status == SS_GEOMETRY_FAILED) return fprintf(stderr, "precomputation failed: %s\n", why), 1;

  ss_request* request = NULL; /* simple supports: boundary fixed, the rest moves along z only */
  TRY(ss_request_create(&request));
  const ss_vec3 zero = {0, 0, 0}, press = {0, 0, -100.0};
  for (int k = 0; k < NV; ++k) {
    const int i = k % (N + 1), j = k / (N + 1), boundary = i == 0 || j == 0 || i == N || j == N;
    TRY(ss_request_add_vertex_constraint(request, k, boundary ? 7u : 3u, &zero)); /* axes: 1 x, 2 y, 4 z */
  }
  const ss_surface_point centre = {(N / 2) * N + N / 2, 0, 0.0, 0.0}; /* corner (0, 0) of the middle face */
  TRY(ss_request_add_surface_force(request, &centre, &press));

  ss_deformation* operation = NULL; /* deform without blocking: poll once per frame */
  TRY(ss_session_deform_begin(session, &id, request, &operation));
  int32_t ready = 0, frames = 0, count = 0;
  for (; !ready; ++frames) {
    TRY(ss_deformation_poll(operation, &ready));
    if (!ready) frame();
  }
  uint32_t res_id = 0;
  TRY(ss_deformation_read(operation, &res_id, deformed, NV, &count));

  ss_evaluator* surface = NULL; /* the limit surface at the centre, deformed */
  ss_limit_sample at;
  TRY(ss_evaluator_create(mesh, &surface));
  TRY(ss_evaluator_evaluate(surface, &centre, deformed, count, &at));
  const double nu = steel.poisson_ratio, D = steel.youngs_modulus * pow(steel.thickness, 3) / (12 * (1 - nu * nu));
  const double w = -at.position.z, reference = 0.01160 * -press.z / D;
  printf("C ABI: result %u after %d frames; centre deflection %.4f mm, plate theory %.4f mm (%+.2f%%)\n", res_id,
         (int)frames, 1e3 * w, 1e3 * reference, 100.0 * (w / reference - 1.0));
  ss_evaluator_destroy(surface);
  ss_deformation_destroy(operation);
  ss_request_destroy(request);
  ss_session_destroy(session);
  ss_mesh_destroy(mesh);
  return fabs(w / reference - 1.0) < 0.02 ? 0 : 1;
}
