/* The C ABI from plain C11: everything that does not need a server (version, generation-checked
 * handles, the log callback, materials, meshes, limit evaluation, tessellation, picking, requests,
 * grab, floor, levels of detail, the error and buffer conventions). The whole-session test is
 * c_api_session_test.c. (Long: plain C has no test framework; one file keeps its few helpers.) */

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "softshell/softshell_c.h"

#include "c_check.h"

static void test_version_and_status(void) {
  CHECK(ss_abi_version() == SS_ABI_VERSION);
  CHECK(strcmp(ss_version(), SS_VERSION_STRING) == 0);
  CHECK(ss_version_number() == SS_VERSION_NUMBER);
  char expected[32];
  snprintf(expected, sizeof expected, "%d.%d.%d", SS_VERSION_MAJOR, SS_VERSION_MINOR, SS_VERSION_PATCH);
  CHECK(strcmp(ss_version(), expected) == 0);
  CHECK(strcmp(ss_status_name(SS_OK), "ok") == 0);
  CHECK(strcmp(ss_status_name(SS_UNPROCESSABLE), "unprocessable") == 0);
  CHECK(strcmp(ss_status_name(SS_BUFFER_TOO_SMALL), "buffer_too_small") == 0);
  CHECK(strcmp(ss_status_name(12345), "unknown_status") == 0);
  CHECK(ss_last_error_message() != NULL);
}

/* What the log callback received (this test logs from one thread only). */
static int g_warnings = 0;
static char g_last_log[512];
static void on_log(int32_t level, const char* message, void* user_data) {
  if (level == SS_LOG_WARNING) ++g_warnings;
  snprintf(g_last_log, sizeof g_last_log, "%s", message);
  ++*(int*)user_data;
}

/* Handles are generation-checked: a destroyed handle is recognised, also once its slot holds a
 * new object, and destroying it again neither releases the new object nor crashes. */
static void test_handles(void) {
  int calls = 0;
  CHECK_OK(ss_set_log_callback(on_log, &calls, SS_LOG_WARNING));
  CHECK_STATUS(ss_set_log_callback(on_log, &calls, 7), SS_INVALID_ARGUMENT);
  int32_t nv = 0, nf = 0;
  ss_mesh* old = make_grid(1);
  CHECK_OK(ss_mesh_counts(old, &nv, &nf));
  ss_mesh_destroy(old);
  CHECK_STATUS(ss_mesh_counts(old, &nv, &nf), SS_INVALID_ARGUMENT);
  CHECK(strstr(ss_last_error_message(), "destroyed") != NULL);

  ss_mesh* reused = make_grid(2); /* takes the freed slot: same index, next generation */
  CHECK(reused != old);
  CHECK_STATUS(ss_mesh_counts(old, &nv, &nf), SS_INVALID_ARGUMENT);
  CHECK(strstr(ss_last_error_message(), "destroyed") != NULL);
  CHECK(calls == 0);
  ss_mesh_destroy(old); /* a second destroy: logged, the new mesh is untouched */
  CHECK(g_warnings == 1 && strstr(g_last_log, "ss_mesh_destroy") != NULL);
  CHECK_OK(ss_mesh_counts(reused, &nv, &nf));
  CHECK(nv == 9 && nf == 4);

  /* A handle of another kind, and values softshell never made. */
  ss_evaluator* ev = NULL;
  CHECK_OK(ss_evaluator_create(reused, &ev));
  CHECK_STATUS(ss_mesh_counts((const ss_mesh*)ev, &nv, &nf), SS_INVALID_ARGUMENT);
  CHECK(strstr(ss_last_error_message(), "is an ss_evaluator, not an ss_mesh") != NULL);
  ss_mesh_destroy((ss_mesh*)ev); /* not a mesh: nothing released, logged */
  CHECK(g_warnings == 2);
  int32_t subfaces = 0;
  CHECK_OK(ss_evaluator_num_subfaces(ev, 0, &subfaces));
  CHECK_STATUS(ss_mesh_counts((const ss_mesh*)(uintptr_t)0x1, &nv, &nf), SS_INVALID_ARGUMENT);
  CHECK(strstr(ss_last_error_message(), "not a handle made by softshell") != NULL);
  CHECK_STATUS(ss_mesh_counts((const ss_mesh*)(uintptr_t)0x7fffffff, &nv, &nf), SS_INVALID_ARGUMENT);
  ss_evaluator_destroy(ev);
  ss_mesh_destroy(reused);

  CHECK_OK(ss_set_log_callback(NULL, NULL, SS_LOG_OFF));
  ss_mesh_destroy(reused); /* no callback: nothing logged */
  CHECK(g_warnings == 2);
}

static void test_materials(void) {
  ss_material m;
  ss_material_default(&m);
  CHECK(m.youngs_modulus == 6.9e10 && m.poisson_ratio == 0.33 && m.thickness == 0.001);
  CHECK_OK(ss_material_check(&m));
  m.poisson_ratio = 0.5;
  CHECK_STATUS(ss_material_check(&m), SS_UNPROCESSABLE);
  CHECK(strstr(ss_last_error_message(), "Poisson") != NULL);
  CHECK_STATUS(ss_material_check(NULL), SS_INVALID_ARGUMENT);

  CHECK_OK(ss_material_preset("Steel", 0.002, &m));
  CHECK(m.youngs_modulus == 2.0e11 && m.poisson_ratio == 0.30 && m.thickness == 0.002 && m.density == 7850);
  CHECK_STATUS(ss_material_preset("unobtainium", 0.001, &m), SS_INVALID_ARGUMENT);
  CHECK(strstr(ss_last_error_message(), "known: aluminium") != NULL);
  CHECK_STATUS(ss_material_preset("rubber", -1.0, &m), SS_INVALID_ARGUMENT);

  const int32_t n = ss_material_preset_count();
  CHECK(n == 11);
  int found_rubber = 0;
  for (int32_t i = 0; i < n; ++i) {
    const char* name = NULL;
    const char* description = NULL;
    double yield = 0.0;
    CHECK_OK(ss_material_preset_at(i, &name, &description, &m, &yield));
    CHECK(name != NULL && description != NULL && strlen(description) > 0 && yield > 0.0);
    CHECK_OK(ss_material_check(&m));
    if (strcmp(name, "rubber") == 0) found_rubber = m.youngs_modulus == 5.0e6;
  }
  CHECK(found_rubber);
  CHECK_STATUS(ss_material_preset_at(n, NULL, NULL, NULL, NULL), SS_INVALID_ARGUMENT);
}

static void test_mesh(void) {
  ss_mesh* mesh = make_grid(4);
  CHECK(mesh != NULL);
  int32_t nv = 0, nf = 0;
  CHECK_OK(ss_mesh_counts(mesh, &nv, &nf));
  CHECK(nv == 25 && nf == 16);
  CHECK_OK(ss_mesh_validate(mesh));

  /* Buffer convention: size query, too small, exact. */
  int32_t count = -1;
  CHECK_OK(ss_mesh_positions(mesh, NULL, 0, &count));
  CHECK(count == 25);
  double small[3 * 3];
  count = -1;
  CHECK_STATUS(ss_mesh_positions(mesh, small, 3, &count), SS_BUFFER_TOO_SMALL);
  CHECK(count == 25);
  CHECK(strlen(ss_last_error_message()) > 0);
  double xyz[3 * 25];
  CHECK_OK(ss_mesh_positions(mesh, xyz, 25, &count));
  CHECK(strlen(ss_last_error_message()) == 0); /* cleared by a successful call */
  CHECK(fabs(xyz[3 * 24 + 0] - 1.0) < 1e-15 && fabs(xyz[3 * 24 + 1] - 1.0) < 1e-15);
  CHECK_STATUS(ss_mesh_positions(mesh, NULL, 5, &count), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_mesh_positions(mesh, xyz, 25, NULL), SS_INVALID_ARGUMENT);

  int32_t num_faces = 0, num_indices = 0;
  CHECK_OK(ss_mesh_faces(mesh, NULL, 0, &num_faces, NULL, 0, &num_indices));
  CHECK(num_faces == 16 && num_indices == 64);
  int32_t sizes[16], indices[64];
  CHECK_STATUS(ss_mesh_faces(mesh, sizes, 16, &num_faces, indices, 10, &num_indices), SS_BUFFER_TOO_SMALL);
  CHECK_OK(ss_mesh_faces(mesh, sizes, 16, &num_faces, indices, 64, &num_indices));
  CHECK(sizes[0] == 4 && indices[0] == 0 && indices[1] == 1 && indices[2] == 6 && indices[3] == 5);

  /* Positions can be replaced (same count only). */
  xyz[3 * 12 + 2] = 0.01;
  CHECK_OK(ss_mesh_set_positions(mesh, xyz, 25));
  CHECK_STATUS(ss_mesh_set_positions(mesh, xyz, 24), SS_INVALID_ARGUMENT);
  xyz[0] = NAN;
  CHECK_STATUS(ss_mesh_set_positions(mesh, xyz, 25), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_mesh_set_boundary(mesh, 7), SS_INVALID_ARGUMENT);
  CHECK_OK(ss_mesh_set_boundary(mesh, SS_BOUNDARY_EDGE_AND_CORNER));
  CHECK_STATUS(ss_mesh_add_crease(mesh, 0, 0, 1.0f), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_mesh_add_crease(mesh, 0, 1, -1.0f), SS_INVALID_ARGUMENT);

  /* Malformed input: errors with a message, no crash. */
  ss_mesh* bad = (ss_mesh*)0x1;
  const double tri[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  const int32_t three = 3;
  const int32_t out_of_range[3] = {0, 1, 3};
  CHECK_STATUS(ss_mesh_create(tri, 3, &three, 1, out_of_range, 3, &bad), SS_INVALID_ARGUMENT);
  CHECK(bad == NULL);
  CHECK(strstr(ss_last_error_message(), "out of range") != NULL);
  const int32_t ok_face[3] = {0, 1, 2};
  CHECK_STATUS(ss_mesh_create(tri, 3, &three, 1, ok_face, 2, &bad), SS_INVALID_ARGUMENT);
  const int32_t two = 2;
  CHECK_STATUS(ss_mesh_create(tri, 3, &two, 1, ok_face, 2, &bad), SS_INVALID_ARGUMENT);
  const double nan_tri[9] = {0, 0, 0, 1, NAN, 0, 0, 1, 0};
  CHECK_STATUS(ss_mesh_create(nan_tri, 3, &three, 1, ok_face, 3, &bad), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_mesh_create(NULL, 3, &three, 1, ok_face, 3, &bad), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_mesh_create(tri, -1, &three, 1, ok_face, 3, &bad), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_mesh_create(tri, 3, &three, 1, ok_face, 3, NULL), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_mesh_counts(NULL, &nv, &nf), SS_INVALID_ARGUMENT);
  CHECK(strstr(ss_last_error_message(), "NULL") != NULL);

  /* A handle of the wrong kind is detected. */
  ss_request* request = NULL;
  CHECK_OK(ss_request_create(&request));
  CHECK_STATUS(ss_mesh_counts((const ss_mesh*)request, &nv, &nf), SS_INVALID_ARGUMENT);
  CHECK(strstr(ss_last_error_message(), "ss_mesh") != NULL);
  ss_request_destroy(request);

  /* An unusable mesh: a control point used by no face. */
  const double four[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 5, 5, 5};
  ss_mesh* unused = NULL;
  CHECK_OK(ss_mesh_create(four, 4, &three, 1, ok_face, 3, &unused));
  CHECK_STATUS(ss_mesh_validate(unused), SS_UNPROCESSABLE);
  ss_evaluator* ev = NULL;
  CHECK(ss_evaluator_create(unused, &ev) != SS_OK);
  CHECK(ev == NULL);
  ss_mesh_destroy(unused);

  ss_mesh* missing = NULL;
  CHECK_STATUS(ss_mesh_read_obj("/nonexistent/softshell/mesh.obj", &missing), SS_IO_ERROR);
  CHECK_STATUS(ss_mesh_read_obj(NULL, &missing), SS_INVALID_ARGUMENT);

  ss_mesh_destroy(mesh);
  ss_mesh_destroy(NULL); /* every destroy accepts NULL */
}

static void test_evaluator(void) {
  ss_mesh* mesh = make_grid(4);
  ss_evaluator* ev = NULL;
  CHECK_OK(ss_evaluator_create(mesh, &ev));
  ss_mesh_destroy(mesh); /* the evaluator keeps its own copy */

  const ss_surface_point p = {5, 0, 0.5, 0.25};
  ss_limit_sample s;
  CHECK_OK(ss_evaluator_evaluate(ev, &p, NULL, 0, &s));
  CHECK(fabs(s.position.z) < 1e-15);
  CHECK(fabs(s.normal.z - 1.0) < 1e-12);
  CHECK(s.du.x > 0.0 && s.dv.y > 0.0);

  /* Deformed control points: a rigid lift moves the limit point by the same amount. */
  double xyz[3 * 25];
  int32_t count = 0;
  ss_mesh* again = make_grid(4);
  CHECK_OK(ss_mesh_positions(again, xyz, 25, &count));
  ss_mesh_destroy(again);
  for (int i = 0; i < 25; ++i) xyz[3 * i + 2] += 0.5;
  ss_limit_sample lifted;
  CHECK_OK(ss_evaluator_evaluate(ev, &p, xyz, 25, &lifted));
  CHECK(fabs(lifted.position.z - 0.5) < 1e-12);
  CHECK_STATUS(ss_evaluator_evaluate(ev, &p, xyz, 24, &lifted), SS_INVALID_ARGUMENT);

  /* Stencil: size query, then weights that sum to 1 (position) and 0 (tangents). */
  CHECK_OK(ss_evaluator_stencil(ev, &p, NULL, NULL, NULL, NULL, 0, &count));
  CHECK(count == 16);
  int32_t indices[16];
  double w[16], wu[16], wv[16];
  CHECK_OK(ss_evaluator_stencil(ev, &p, indices, w, wu, wv, 16, &count));
  double sum = 0.0, sum_u = 0.0;
  for (int k = 0; k < count; ++k) {
    sum += w[k];
    sum_u += wu[k];
    CHECK(indices[k] >= 0 && indices[k] < 25);
  }
  CHECK(fabs(sum - 1.0) < 1e-14 && fabs(sum_u) < 1e-12);
  CHECK_OK(ss_evaluator_stencil(ev, &p, indices, NULL, NULL, NULL, 16, &count)); /* weights optional */

  int32_t subfaces = 0;
  CHECK_OK(ss_evaluator_num_subfaces(ev, 0, &subfaces));
  CHECK(subfaces == 1);
  CHECK_STATUS(ss_evaluator_num_subfaces(ev, 16, &subfaces), SS_INVALID_ARGUMENT);

  /* Bad points. */
  const ss_surface_point bad_face = {99, 0, 0.5, 0.5}, bad_uv = {0, 0, 1.5, 0.5}, bad_sub = {0, 1, 0.5, 0.5};
  const ss_surface_point nan_uv = {0, 0, NAN, 0.5};
  CHECK_STATUS(ss_evaluator_evaluate(ev, &bad_face, NULL, 0, &s), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_evaluator_evaluate(ev, &bad_uv, NULL, 0, &s), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_evaluator_evaluate(ev, &bad_sub, NULL, 0, &s), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_evaluator_evaluate(ev, &nan_uv, NULL, 0, &s), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_evaluator_evaluate(ev, NULL, NULL, 0, &s), SS_INVALID_ARGUMENT);
  ss_evaluator_destroy(ev);
}

static void test_tessellation_and_picking(void) {
  ss_mesh* mesh = make_grid(4);
  ss_evaluator* ev = NULL;
  CHECK_OK(ss_evaluator_create(mesh, &ev));
  ss_tessellation* tess = NULL;
  CHECK_STATUS(ss_tessellation_create(ev, 9, &tess), SS_INVALID_ARGUMENT);
  CHECK_OK(ss_tessellation_create(ev, 3, &tess));
  int32_t nv = 0, nt = 0;
  CHECK_OK(ss_tessellation_counts(tess, &nv, &nt));
  CHECK(nv == 33 * 33 && nt == 2 * 32 * 32);
  float* vertices = malloc(sizeof(float) * 3 * (size_t)nv);
  float* normals = malloc(sizeof(float) * 3 * (size_t)nv);
  int32_t* triangles = malloc(sizeof(int32_t) * 3 * (size_t)nt);
  int32_t count = 0;
  CHECK_OK(ss_tessellation_vertices(tess, vertices, nv, &count));
  CHECK(count == nv);
  CHECK_OK(ss_tessellation_normals(tess, normals, nv, &count));
  CHECK(fabsf(normals[2] - 1.0f) < 1e-6f);
  CHECK_OK(ss_tessellation_triangles(tess, triangles, nt, &count));
  CHECK(count == nt);
  int in_range = 1;
  for (int i = 0; i < 3 * nt; ++i) in_range &= triangles[i] >= 0 && triangles[i] < nv;
  CHECK(in_range);

  ss_picker* picker = NULL;
  CHECK_OK(ss_picker_create(tess, &picker));
  ss_tessellation_destroy(tess); /* the picker keeps it alive */

  const ss_ray down = {{0.3, 0.6, 2.0}, {0.0, 0.0, -1.0}, 0.0, INFINITY};
  ss_pick pick;
  int32_t hit = 0;
  CHECK_OK(ss_picker_pick(picker, &down, 1, &pick, &hit));
  CHECK(hit == 1);
  CHECK(pick.status == SS_REFINE_CONVERGED);
  CHECK(pick.distance_to_ray < 1e-12);
  CHECK(fabs(pick.t - 2.0) < 1e-12);
  CHECK(fabs(pick.position.x - 0.3) < 1e-12 && fabs(pick.position.y - 0.6) < 1e-12);
  CHECK(pick.point.face >= 0 && pick.point.face < 16 && pick.point.u >= 0.0 && pick.point.u <= 1.0);
  ss_limit_sample s;
  CHECK_OK(ss_evaluator_evaluate(ev, &pick.point, NULL, 0, &s));
  CHECK(fabs(s.position.x - 0.3) < 1e-12 && fabs(s.position.y - 0.6) < 1e-12);

  /* Misses and bad rays. */
  const ss_ray away = {{0.3, 0.6, 2.0}, {0.0, 0.0, 1.0}, 0.0, INFINITY};
  CHECK_OK(ss_picker_pick(picker, &away, 1, &pick, &hit));
  CHECK(hit == 0);
  const ss_ray nan_ray = {{NAN, 0.6, 2.0}, {0.0, 0.0, -1.0}, 0.0, INFINITY};
  CHECK_STATUS(ss_picker_pick(picker, &nan_ray, 1, &pick, &hit), SS_INVALID_ARGUMENT);
  const ss_ray zero_dir = {{0.3, 0.6, 2.0}, {0.0, 0.0, 0.0}, 0.0, INFINITY};
  CHECK_STATUS(ss_picker_pick(picker, &zero_dir, 1, &pick, &hit), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_picker_pick(picker, NULL, 1, &pick, &hit), SS_INVALID_ARGUMENT);

  /* Deform (lift by 0.5), update the tessellation, refit: the pick follows. */
  double xyz[3 * 25];
  CHECK_OK(ss_mesh_positions(mesh, xyz, 25, &count));
  for (int i = 0; i < 25; ++i) xyz[3 * i + 2] += 0.5;
  ss_tessellation* tess2 = NULL;
  CHECK_OK(ss_tessellation_create(ev, 2, &tess2));
  ss_picker* picker2 = NULL;
  CHECK_OK(ss_picker_create(tess2, &picker2));
  CHECK_OK(ss_tessellation_update(tess2, xyz, 25));
  CHECK_STATUS(ss_tessellation_update(tess2, xyz, 3), SS_INVALID_ARGUMENT);
  CHECK_OK(ss_picker_refit(picker2));
  CHECK_OK(ss_picker_pick(picker2, &down, 1, &pick, &hit));
  CHECK(hit == 1 && fabs(pick.t - 1.5) < 1e-12 && fabs(pick.position.z - 0.5) < 1e-12);

  free(vertices);
  free(normals);
  free(triangles);
  ss_picker_destroy(picker2);
  ss_tessellation_destroy(tess2);
  ss_picker_destroy(picker);
  ss_evaluator_destroy(ev);
  ss_mesh_destroy(mesh);
}

static void test_requests_grab_floor(void) {
  ss_mesh* mesh = make_grid(4);
  ss_evaluator* ev = NULL;
  CHECK_OK(ss_evaluator_create(mesh, &ev));
  ss_tessellation* tess = NULL;
  CHECK_OK(ss_tessellation_create(ev, 2, &tess));
  ss_request* req = NULL;
  CHECK_OK(ss_request_create(&req));

  const ss_vec3 zero = {0, 0, 0}, down = {0, 0, -1}, nan3 = {NAN, 0, 0};
  CHECK_OK(ss_request_add_vertex_constraint(req, 0, 7, &zero));
  CHECK_STATUS(ss_request_add_vertex_constraint(req, 0, 0, &zero), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_request_add_vertex_constraint(req, 0, 8, &zero), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_request_add_vertex_constraint(req, -1, 7, &zero), SS_INVALID_ARGUMENT);
  CHECK_STATUS(ss_request_add_vertex_constraint(req, 0, 7, &nan3), SS_INVALID_ARGUMENT);
  CHECK_OK(ss_request_add_force(req, 12, &down));
  const ss_surface_point p = {5, 0, 0.5, 0.5};
  CHECK_OK(ss_request_add_surface_force(req, &p, &down));
  const ss_vec3 tangent = {0.1, 0, 0};
  CHECK_OK(ss_request_add_limit_constraint(req, &p, &down, &tangent, NULL));
  const int32_t idx[2] = {1, 2};
  const ss_vec3 coef[2] = {{1, 1, 1}, {-1, -1, -1}};
  CHECK_OK(ss_request_add_lagrange_constraint(req, idx, coef, 2, &zero));
  CHECK_STATUS(ss_request_add_lagrange_constraint(req, idx, coef, 0, &zero), SS_INVALID_ARGUMENT);
  CHECK_OK(ss_request_set_surface_load(req, &down));
  CHECK_OK(ss_request_set_pressure(req, 1.0));
  CHECK_STATUS(ss_request_set_pressure(req, NAN), SS_INVALID_ARGUMENT);

  /* The whole plate lies on the floor z = 0: one point per face, all rigid motions fixed. */
  const ss_vec3 origin = {0, 0, 0}, up = {0, 0, 1}, tilted = {0, 0.1, 1};
  ss_floor_options floor_options;
  ss_floor_options_default(&floor_options);
  CHECK(floor_options.tolerance < 0.0 && floor_options.normal_only == 0);
  int32_t points = 0, fixes = 0;
  CHECK_OK(ss_request_add_floor(req, tess, &origin, &up, &floor_options, &points, &fixes));
  CHECK(points == 16 && fixes == 1);
  floor_options.normal_only = 1;
  CHECK_STATUS(ss_request_add_floor(req, tess, &origin, &tilted, &floor_options, &points, &fixes),
               SS_INVALID_ARGUMENT);

  /* Grab the centre with a hand above it, lift the hand: the target follows. */
  const ss_pose hand = {{0.5, 0.5, 1.0}, {0, 0, 0, 1}};
  const ss_surface_point centre = {10, 0, 0.0, 0.0}; /* corner of face 10 = the plate's centre */
  ss_grab_options grab_options;
  ss_grab_options_default(&grab_options);
  CHECK(grab_options.follow_rotation == 1 && grab_options.constrain_tangents == 0);
  ss_grab* grab = NULL;
  CHECK_OK(ss_grab_begin(ev, &centre, NULL, 0, &hand, &grab_options, &grab));
  const ss_pose lifted = {{0.5, 0.5, 1.2}, {0, 0, 0, 1}};
  ss_vec3 target;
  CHECK_OK(ss_grab_target(grab, &lifted, &target));
  CHECK(fabs(target.x - 0.5) < 1e-12 && fabs(target.y - 0.5) < 1e-12 && fabs(target.z - 0.2) < 1e-12);
  CHECK_OK(ss_request_add_grab(req, grab, &lifted));
  const ss_pose bad_hand = {{0.5, 0.5, 1.0}, {0, 0, 0, 0}};
  CHECK_STATUS(ss_request_add_grab(req, grab, &bad_hand), SS_INVALID_ARGUMENT);
  ss_grab* bad_grab = NULL;
  CHECK_STATUS(ss_grab_begin(ev, &centre, NULL, 0, &bad_hand, NULL, &bad_grab), SS_INVALID_ARGUMENT);
  CHECK(bad_grab == NULL);

  int32_t nvc = 0, nlag = 0, nforce = 0, nlimit = 0, nsurf = 0;
  CHECK_OK(ss_request_counts(req, &nvc, &nlag, &nforce, &nlimit, &nsurf));
  CHECK(nvc == 1 && nlag == 1 && nforce == 1 && nsurf == 1);
  CHECK(nlimit == 1 + 16 + 1); /* explicit + floor + grab */
  CHECK_OK(ss_request_clear(req));
  CHECK_OK(ss_request_counts(req, &nvc, NULL, NULL, &nlimit, NULL));
  CHECK(nvc == 0 && nlimit == 0);

  ss_grab_destroy(grab);
  ss_request_destroy(req);
  ss_tessellation_destroy(tess);
  ss_evaluator_destroy(ev);
  ss_mesh_destroy(mesh);
}

static void test_levels_of_detail(void) {
  ss_mesh* coarse = make_grid(3);
  ss_refinement* r = NULL;
  CHECK_STATUS(ss_refinement_create(coarse, 0, &r), SS_INVALID_ARGUMENT);
  CHECK_OK(ss_refinement_create(coarse, 1, &r));
  ss_mesh* fine = NULL;
  CHECK_OK(ss_refinement_fine_mesh(r, &fine));
  int32_t nv = 0, nf = 0;
  CHECK_OK(ss_mesh_counts(fine, &nv, &nf));
  CHECK(nv == 49 && nf == 36);

  /* The same limit point on both levels. */
  ss_evaluator *ec = NULL, *ef = NULL;
  CHECK_OK(ss_evaluator_create(coarse, &ec));
  CHECK_OK(ss_evaluator_create(fine, &ef));
  const ss_surface_point p = {4, 0, 0.3, 0.8};
  ss_surface_point q;
  CHECK_OK(ss_refinement_fine_point(r, &p, &q));
  ss_limit_sample a, b;
  CHECK_OK(ss_evaluator_evaluate(ec, &p, NULL, 0, &a));
  CHECK_OK(ss_evaluator_evaluate(ef, &q, NULL, 0, &b));
  CHECK(fabs(a.position.x - b.position.x) < 1e-12 && fabs(a.position.y - b.position.y) < 1e-12);

  /* x_f = S x_c. */
  double xc[3 * 16], xf[3 * 49];
  int32_t count = 0;
  CHECK_OK(ss_mesh_positions(coarse, xc, 16, &count));
  CHECK_OK(ss_refinement_refine_positions(r, xc, 16, NULL, 0, &count));
  CHECK(count == 49);
  CHECK_OK(ss_refinement_refine_positions(r, xc, 16, xf, 49, &count));
  double yf[3 * 49];
  CHECK_OK(ss_mesh_positions(fine, yf, 49, &count));
  double worst = 0.0;
  for (int i = 0; i < 3 * 49; ++i) worst = fmax(worst, fabs(xf[i] - yf[i]));
  CHECK(worst < 1e-15);

  /* Requests: a force keeps its total on the fine mesh. */
  ss_request *req = NULL, *fine_req = NULL;
  CHECK_OK(ss_request_create(&req));
  const ss_vec3 f = {0, 0, -2};
  CHECK_OK(ss_request_add_force(req, 5, &f));
  CHECK_OK(ss_request_add_limit_constraint(req, &p, &f, NULL, NULL));
  CHECK_STATUS(ss_refinement_request_to_fine(r, req, 5, &fine_req), SS_INVALID_ARGUMENT);
  CHECK_OK(ss_refinement_request_to_fine(r, req, SS_FORCE_TRANSFER_SUBDIVIDE, &fine_req));
  int32_t nforce = 0, nlimit = 0;
  CHECK_OK(ss_request_counts(fine_req, NULL, NULL, &nforce, &nlimit, NULL));
  CHECK(nforce > 1 && nlimit == 1);
  const ss_vec3 far_force = {1, 0, 0};
  CHECK_OK(ss_request_add_force(req, 16, &far_force)); /* index valid for the C call, not for the mesh */
  ss_request* rejected = NULL;
  CHECK_STATUS(ss_refinement_request_to_fine(r, req, SS_FORCE_TRANSFER_SUBDIVIDE, &rejected), SS_INVALID_ARGUMENT);
  CHECK(rejected == NULL);

  ss_request_destroy(req);
  ss_request_destroy(fine_req);
  ss_evaluator_destroy(ec);
  ss_evaluator_destroy(ef);
  ss_mesh_destroy(fine);
  ss_refinement_destroy(r);
  ss_mesh_destroy(coarse);
}

static void test_ngon_mesh_from_obj(void) {
  ss_mesh* mesh = NULL;
  CHECK_OK(ss_mesh_read_obj(SOFTSHELL_ASSET_DIR "/meshes/catmark_nonquads.obj", &mesh));
  if (!mesh) return;
  ss_evaluator* ev = NULL;
  CHECK_OK(ss_evaluator_create(mesh, &ev));
  int32_t nf = 0;
  CHECK_OK(ss_mesh_counts(mesh, NULL, &nf));
  int32_t ngons = 0;
  for (int32_t f = 0; f < nf; ++f) {
    int32_t n = 0;
    CHECK_OK(ss_evaluator_num_subfaces(ev, f, &n));
    ngons += n != 1;
  }
  CHECK(ngons > 0);
  ss_tessellation* tess = NULL;
  CHECK_OK(ss_tessellation_create(ev, 2, &tess));
  ss_picker* picker = NULL;
  CHECK_OK(ss_picker_create(tess, &picker));
  /* The four shapes lie in the XZ plane: a grid of slanted rays from above. */
  int hits = 0, converged = 0;
  for (int i = 0; i < 20; ++i) {
    for (int j = 0; j < 20; ++j) {
      const ss_vec3 o = {-2.5 + 0.25 * i, 3.0, -2.5 + 0.25 * j};
      const ss_ray ray = {o, {0.1, -1.0, 0.05}, 0.0, INFINITY};
      ss_pick pick;
      int32_t hit = 0;
      CHECK_OK(ss_picker_pick(picker, &ray, 1, &pick, &hit));
      hits += hit;
      if (hit && pick.status == SS_REFINE_CONVERGED) {
        ++converged;
        CHECK(pick.distance_to_ray < 1e-9);
      }
    }
  }
  CHECK(hits > 20 && converged == hits);
  ss_picker_destroy(picker);
  ss_tessellation_destroy(tess);
  ss_evaluator_destroy(ev);
  ss_mesh_destroy(mesh);
}

static void test_sessions_need_handles(void) {
  ss_mesh* mesh = make_grid(2);
  const ss_material material = {6.9e10, 0.33, 0.001, 2700.0};
  ss_geom_id id;
  memset(&id, 0, sizeof id);
  CHECK_STATUS(ss_session_upload(NULL, mesh, &material, NULL, &id, NULL), SS_INVALID_ARGUMENT);
  ss_deformation* op = NULL;
  CHECK_STATUS(ss_session_deform_begin(NULL, &id, NULL, &op), SS_INVALID_ARGUMENT);
  CHECK(op == NULL);
  int32_t ready = 0;
  CHECK_STATUS(ss_deformation_poll(NULL, &ready), SS_INVALID_ARGUMENT);
  char hex[33];
  id.bytes[0] = 0xab;
  id.bytes[15] = 0x01;
  CHECK_OK(ss_geom_id_to_hex(&id, hex, 33));
  CHECK(strcmp(hex, "ab000000000000000000000000000001") == 0);
  CHECK_STATUS(ss_geom_id_to_hex(&id, hex, 32), SS_BUFFER_TOO_SMALL);
  ss_session_destroy(NULL);
  ss_deformation_destroy(NULL);
  ss_mesh_destroy(mesh);
}

int main(void) {
  test_version_and_status();
  test_handles();
  test_materials();
  test_mesh();
  test_evaluator();
  test_tessellation_and_picking();
  test_requests_grab_floor();
  test_levels_of_detail();
  test_ngon_mesh_from_obj();
  test_sessions_need_handles();
  printf("c_api_test: %d checks, %d failures\n", g_checks, g_failures);
  return g_failures == 0 ? 0 : 1;
}
