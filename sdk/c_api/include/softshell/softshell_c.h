/*
 * softshell C ABI: the SDK for Unity (P/Invoke), Unreal and plain C.
 *
 * Conventions (every function follows them):
 *  - Objects are opaque handles made by a `ss_<noun>_create...` function and released by the
 *    matching `ss_<noun>_destroy`, which accepts NULL. A handle owns what it needs: e.g. a picker
 *    keeps its tessellation alive, so handles may be destroyed in any order.
 *  - Every other function returns an `ss_status` (int32): SS_OK (0) or an error code. Codes 1..12
 *    are softshell's `ErrorCode` values (result.h); 100 and 101 exist only here. After a failure
 *    `ss_last_error_message()` says what was wrong, for a person; it is thread-local.
 *  - No exception, C++ type or allocation ownership crosses the boundary. Strings are UTF-8,
 *    NUL-terminated, and copied in.
 *  - Arrays going out are written into caller-owned buffers: `(T* out, int32_t capacity,
 *    int32_t* out_count)`, counts in items (an "xyz" item is 3 numbers). `*out_count` is always
 *    set to the number of items available. Passing `out = NULL, capacity = 0` only asks for the
 *    count (SS_OK). A capacity below the count writes nothing and returns SS_BUFFER_TOO_SMALL.
 *  - Arrays coming in are `(const T* in, int32_t count)`. Positions are double precision xyz
 *    triples; rendering outputs (tessellation vertices and normals) are float.
 *  - Bad input (NULL pointers, negative counts, indices out of range, NaN or infinite numbers, a
 *    handle of the wrong kind or already destroyed) is an error, never a crash. Handles are
 *    generation-checked ids (as Box2D's): a handle's value holds a slot of softshell's handle
 *    table and that slot's generation, checked on every call, so a destroyed handle is always
 *    detected (SS_INVALID_ARGUMENT, "... is a destroyed handle"), also after its slot was reused.
 *    The value is never dereferenced: it is an opaque token of pointer size. Destroying a handle
 *    twice releases nothing and logs a warning (ss_set_log_callback).
 *  - Units: the mesh's length unit (metres with SI materials); forces in N; E in Pa.
 *  - Thread-safety: a handle may be used by one thread at a time, except: functions taking a
 *    `const` handle (evaluate, pick, ...) may run concurrently on it as long as no non-const
 *    function runs on it at the same time; sessions and deformation operations are thread-safe.
 *    A call in progress keeps its object alive even if another thread destroys the handle.
 *
 * Asynchronous deformation never blocks a game thread: `ss_session_deform_begin` returns an
 * operation at once; `ss_deformation_poll` says whether it is done; `ss_deformation_read` copies
 * the result out. Destroying an operation (or its session) while it runs is allowed and does not
 * block; the request completes in the background. Calls that ask a session something
 * (`ss_session_geometry_status`, `ss_session_limit_comb`, upload) answer at once in-process and
 * take one round trip on a remote session.
 *
 * Not yet in the C ABI: a host task callback for the server's threads (the C++ `Executor`).
 */
#ifndef SOFTSHELL_C_H
#define SOFTSHELL_C_H

#include <stdint.h>

#if defined(_WIN32)
#  if defined(SOFTSHELL_SDK_BUILDING)
#    define SS_API __declspec(dllexport)
#  else
#    define SS_API __declspec(dllimport)
#  endif
#else
#  define SS_API __attribute__((visibility("default")))
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* ---------------------------------------------------------------------------------------------
 * Version and status */

/** softshell's version (the release this header belongs to). */
#define SS_VERSION_MAJOR 0
#define SS_VERSION_MINOR 2
#define SS_VERSION_PATCH 0
#define SS_VERSION_STRING "0.2.0"
/** The version as one number, (major << 16) | (minor << 8) | patch, e.g. 0x000100 for 0.1.0. */
#define SS_VERSION_NUMBER ((SS_VERSION_MAJOR << 16) | (SS_VERSION_MINOR << 8) | SS_VERSION_PATCH)
/** The version of the loaded library, e.g. "0.2.0" (static storage). */
SS_API const char* ss_version(void);
/** The same as one number (SS_VERSION_NUMBER of the library's build). */
SS_API uint32_t ss_version_number(void);

/** The ABI version this header describes; compare with `ss_abi_version()` at load time and refuse
 *  a library with another one (struct layouts or signatures differ). 2: generation-checked
 *  handles, blittable ss_embedded_options, geometry status, presets, limit_comb, log callback.
 *  3: ss_remote_options.auth_token. 4: ss_session_remove_geometry; ss_embedded_options gains
 *  keep_results, result_budget_mb and data_dir (96 bytes on 64-bit platforms, was 80). */
#define SS_ABI_VERSION 4u
/** The ABI version of the loaded library. */
SS_API uint32_t ss_abi_version(void);

typedef int32_t ss_status;
#define SS_OK 0
#define SS_INVALID_ARGUMENT 1      /* malformed input: NULL, out of range, NaN */
#define SS_UNPROCESSABLE 2         /* well-formed but unusable: undetermined system, bad material */
#define SS_NOT_FOUND 3             /* unknown geometry or result */
#define SS_PAYLOAD_TOO_LARGE 4
#define SS_UNSUPPORTED_MEDIA_TYPE 5
#define SS_NOT_ACCEPTABLE 6
#define SS_RESOURCE_EXHAUSTED 7    /* out of memory or over a configured limit */
#define SS_UNAVAILABLE 8           /* server unreachable, timed out or shutting down */
#define SS_CANCELLED 9
#define SS_IO_ERROR 10             /* a file could not be read or written */
#define SS_INTERNAL 11             /* a bug in softshell; please report it */
#define SS_CONFLICT 12             /* contradicts other clients' holds (HTTP 409) */
#define SS_GONE 13                 /* no longer kept: a result dropped by retention, a deleted geometry (HTTP 410) */
#define SS_BUFFER_TOO_SMALL 100    /* C ABI only: `capacity` is below `*out_count` */
#define SS_NOT_READY 101           /* C ABI only: an asynchronous operation has not finished */

/** What the last failing call on this thread reported ("" after a successful call). Valid until
 *  the next softshell call on this thread. Never NULL. */
SS_API const char* ss_last_error_message(void);
/** Short stable name of a status, e.g. "invalid_argument". Never NULL; static storage. */
SS_API const char* ss_status_name(ss_status status);

/* ---------------------------------------------------------------------------------------------
 * Log */

#define SS_LOG_DEBUG 0
#define SS_LOG_INFO 1
#define SS_LOG_WARNING 2
#define SS_LOG_ERROR 3
#define SS_LOG_OFF 4

/** Receives one message (UTF-8, no trailing newline, valid during the call only). Called from any
 *  thread, softshell's own included, one call at a time; it must return quickly and must not call
 *  back into softshell. */
typedef void (*ss_log_callback)(int32_t level, const char* message, void* user_data);

/** Installs the process-wide log callback (NULL: none, the default) with the lowest level it
 *  receives (SS_LOG_*; SS_LOG_OFF silences it). What is logged: the in-process server's messages
 *  (precomputations started, finished and failed, failed solves; with a listener, its requests),
 *  handles destroyed twice, and the errors of operations destroyed before anybody read them.
 *  Errors of calls are still returned as statuses; internal errors (bugs) are also logged. It
 *  becomes the SDK's process-wide log sink (softshell/log.h, `set_log_sink`; it replaces a sink a
 *  C++ host installed there). Takes effect at once, for every session; after it returns with
 *  another callback (or NULL) the old one is not called again. SS_INVALID_ARGUMENT for a level
 *  outside SS_LOG_DEBUG..SS_LOG_OFF. */
SS_API ss_status ss_set_log_callback(ss_log_callback callback, void* user_data, int32_t min_level);

/* ---------------------------------------------------------------------------------------------
 * Plain structs (no padding surprises: every field is 4 or 8 bytes, 8-byte fields 8-aligned) */

typedef struct ss_vec3 {
  double x, y, z;
} ss_vec3;

/** A rotation as a quaternion (need not be normalized; must not be zero). Identity: {0, 0, 0, 1}.
 *  Same component order as Unity's Quaternion and Unreal's FQuat. */
typedef struct ss_quat {
  double x, y, z, w;
} ss_quat;

typedef struct ss_pose {
  ss_vec3 position;
  ss_quat orientation;
} ss_pose;

/** A point of the limit surface (PROTOCOL.md, Conventions): control face, sub-face (0 for quads,
 *  0..n-1 for n-gons) and (u, v) in [0, 1]^2. */
typedef struct ss_surface_point {
  int32_t face;
  int32_t subface;
  double u;
  double v;
} ss_surface_point;

/** Shell material, SI: E (Pa) > 0, Poisson's ratio in (-1, 0.5), thickness (m) > 0, density
 *  (kg/m^3, not sent to the server). */
typedef struct ss_material {
  double youngs_modulus;
  double poisson_ratio;
  double thickness;
  double density;
} ss_material;

/** The built-in defaults (E 69 GPa, nu 0.33, t 1 mm, 2700 kg/m^3: aluminium). No-op for NULL. */
SS_API void ss_material_default(ss_material* out);
/** SS_OK if the material can be simulated; otherwise SS_UNPROCESSABLE naming the field and its
 *  allowed range. */
SS_API ss_status ss_material_check(const ss_material* material);
/** The named preset (case-insensitive: "aluminium", "steel", "rubber", ...) with the given
 *  thickness (m). An unknown name is SS_INVALID_ARGUMENT, the message lists the known ones. */
SS_API ss_status ss_material_preset(const char* name, double thickness, ss_material* out_material);
/** Number of presets (11). */
SS_API int32_t ss_material_preset_count(void);
/** Preset `index` (0..count-1): name and description (static storage), material (thickness 1 mm)
 *  and the stress (Pa) above which the linear elastic model no longer holds. Outputs nullable. */
SS_API ss_status ss_material_preset_at(int32_t index, const char** out_name, const char** out_description,
                                       ss_material* out_material, double* out_yield_strength);

/** Content-derived geometry id (16 bytes). */
typedef struct ss_geom_id {
  uint8_t bytes[16];
} ss_geom_id;

/** The points origin + t * direction with t_min <= t <= t_max (t_max may be INFINITY). */
typedef struct ss_ray {
  ss_vec3 origin;
  ss_vec3 direction;
  double t_min;
  double t_max;
} ss_ray;

/** Limit position, first derivatives (w.r.t. the sub-face's u, v) and unit normal. */
typedef struct ss_limit_sample {
  ss_vec3 position;
  ss_vec3 du;
  ss_vec3 dv;
  ss_vec3 normal;
} ss_limit_sample;

#define SS_REFINE_CONVERGED 0      /* the point lies on the ray */
#define SS_REFINE_AT_BOUNDARY 1    /* the ray passes just outside an open boundary */
#define SS_REFINE_NOT_CONVERGED 2  /* e.g. a grazing ray; the best point found */

/** A picked point: the tessellation's estimate (paper Section 5.1) and the point refined on the
 *  exact limit surface. */
typedef struct ss_pick {
  int32_t triangle;              /* hit triangle of the tessellation */
  int32_t status;                /* SS_REFINE_* */
  ss_surface_point estimate;     /* from the quadtree path and barycentric weights */
  ss_surface_point point;        /* refined (== estimate when refinement is off) */
  ss_vec3 position;              /* limit position at `point` */
  ss_vec3 normal;                /* unit limit normal there */
  ss_vec3 du;
  ss_vec3 dv;
  double t;                      /* ray parameter of `position` */
  double distance_to_ray;        /* distance of `position` from the ray's line */
  double triangle_t;             /* ray parameter of the triangle hit */
  int32_t iterations;            /* Newton steps */
  int32_t face_crossings;        /* moves to neighbouring faces / sub-faces */
} ss_pick;

typedef struct ss_grab_options {
  int32_t follow_rotation;       /* != 0: the point swings with the hand's rotation (default 1) */
  int32_t constrain_tangents;    /* != 0: the tangent plane turns with the hand (default 0) */
} ss_grab_options;
/** Writes the defaults into `*out` (no-op for NULL). */
SS_API void ss_grab_options_default(ss_grab_options* out);

typedef struct ss_floor_options {
  double tolerance;              /* contact distance (length unit); < 0: 1e-3 of the object's size */
  int32_t normal_only;           /* != 0: hold only the normal component (axis-aligned normal) */
  int32_t snap;                  /* != 0: move touching points onto the plane */
} ss_floor_options;
SS_API void ss_floor_options_default(ss_floor_options* out);

/** Force transfer between levels of detail (level_of_detail.h, `ForceTransfer`). */
#define SS_FORCE_TRANSFER_SUBDIVIDE 0
#define SS_FORCE_TRANSFER_VIRTUAL_WORK 1

#define SS_BOUNDARY_EDGE_AND_CORNER 0
#define SS_BOUNDARY_NONE 1

/* ---------------------------------------------------------------------------------------------
 * Handles */

typedef struct ss_mesh ss_mesh;                   /* control mesh (positions, faces, tags) */
typedef struct ss_evaluator ss_evaluator;         /* exact limit surface of a mesh */
typedef struct ss_tessellation ss_tessellation;   /* triangles of the limit surface */
typedef struct ss_picker ss_picker;               /* ray picking on a tessellation */
typedef struct ss_request ss_request;             /* forces and constraints to solve */
typedef struct ss_grab ss_grab;                   /* a grab following a hand */
typedef struct ss_refinement ss_refinement;       /* a mesh refined k levels (level of detail) */
typedef struct ss_session ss_session;             /* connection to a server */
typedef struct ss_deformation ss_deformation;     /* an asynchronous deformation */
typedef struct ss_hold_put ss_hold_put;           /* an asynchronous put of a hold */
typedef struct ss_subscription ss_subscription;   /* a follower of a geometry's results */
typedef struct ss_stress_field ss_stress_field;   /* stresses of a stored result */

/* ---------------------------------------------------------------------------------------------
 * Control mesh */

/** A mesh from arrays: `positions_xyz` (3 * num_vertices doubles), `face_sizes` (num_faces, each
 *  >= 3) and `face_indices` (num_face_indices = sum of the sizes, 0-based, counter-clockwise).
 *  Malformed input (indices out of range, NaN, sizes that do not add up) is SS_INVALID_ARGUMENT;
 *  `ss_mesh_validate` checks what the simulation needs beyond that. */
SS_API ss_status ss_mesh_create(const double* positions_xyz, int32_t num_vertices, const int32_t* face_sizes,
                                int32_t num_faces, const int32_t* face_indices, int32_t num_face_indices,
                                ss_mesh** out_mesh);
/** Reads an OBJ file (faces of any size; `t crease` / `t corner` tags). */
SS_API ss_status ss_mesh_read_obj(const char* path, ss_mesh** out_mesh);
SS_API ss_status ss_mesh_write_obj(const ss_mesh* mesh, const char* path);
SS_API void ss_mesh_destroy(ss_mesh* mesh);

SS_API ss_status ss_mesh_counts(const ss_mesh* mesh, int32_t* out_num_vertices, int32_t* out_num_faces);
/** Control point positions (items: xyz). */
SS_API ss_status ss_mesh_positions(const ss_mesh* mesh, double* out_xyz, int32_t capacity, int32_t* out_count);
/** Replaces the positions (same count). */
SS_API ss_status ss_mesh_set_positions(ss_mesh* mesh, const double* positions_xyz, int32_t count);
/** Face sizes (items: one int32 per face) and face indices (items: one int32 per corner). Both
 *  counts are always set; SS_BUFFER_TOO_SMALL if either buffer is too small. */
SS_API ss_status ss_mesh_faces(const ss_mesh* mesh, int32_t* out_sizes, int32_t sizes_capacity, int32_t* out_num_faces,
                               int32_t* out_indices, int32_t indices_capacity, int32_t* out_num_indices);
/** SS_BOUNDARY_EDGE_AND_CORNER (default) or SS_BOUNDARY_NONE. */
SS_API ss_status ss_mesh_set_boundary(ss_mesh* mesh, int32_t boundary);
/** A sharp (>= 10) or semi-sharp crease on the edge (v0, v1). */
SS_API ss_status ss_mesh_add_crease(ss_mesh* mesh, int32_t v0, int32_t v1, float sharpness);
/** SS_OK if the mesh can be subdivided and simulated; otherwise the first problem (the message
 *  names the face or control point). */
SS_API ss_status ss_mesh_validate(const ss_mesh* mesh);

/* ---------------------------------------------------------------------------------------------
 * Limit surface */

/** Exact limit evaluation (OpenSubdiv Bfr) of a copy of `mesh`. */
SS_API ss_status ss_evaluator_create(const ss_mesh* mesh, ss_evaluator** out_evaluator);
SS_API void ss_evaluator_destroy(ss_evaluator* evaluator);
/** Number of sub-faces of a face (1 for quads, n for n-gons). */
SS_API ss_status ss_evaluator_num_subfaces(const ss_evaluator* evaluator, int32_t face, int32_t* out_count);
/** Limit position, tangents and normal at `point`, for the rest positions (`positions_xyz` NULL,
 *  count 0) or for deformed control points (`count` = the mesh's vertex count). */
SS_API ss_status ss_evaluator_evaluate(const ss_evaluator* evaluator, const ss_surface_point* point,
                                       const double* positions_xyz, int32_t count, ss_limit_sample* out_sample);
/** The limit stencil at `point`: control point indices and the weights of position, du and dv
 *  (items: one per control point; all four buffers have `capacity` items; the weight buffers may
 *  be NULL when not wanted). */
SS_API ss_status ss_evaluator_stencil(const ss_evaluator* evaluator, const ss_surface_point* point,
                                      int32_t* out_indices, double* out_position, double* out_du, double* out_dv,
                                      int32_t capacity, int32_t* out_count);

/* ---------------------------------------------------------------------------------------------
 * Tessellation and picking */

/** Uniform tessellation at `level` (0..8; 0 only for all-quad meshes). Keeps the evaluator's data
 *  alive. */
SS_API ss_status ss_tessellation_create(const ss_evaluator* evaluator, int32_t level, ss_tessellation** out);
SS_API void ss_tessellation_destroy(ss_tessellation* tessellation);
SS_API ss_status ss_tessellation_counts(const ss_tessellation* tessellation, int32_t* out_num_vertices,
                                        int32_t* out_num_triangles);
/** Vertex positions (items: xyz floats), current shape. */
SS_API ss_status ss_tessellation_vertices(const ss_tessellation* tessellation, float* out_xyz, int32_t capacity,
                                          int32_t* out_count);
/** Unit vertex normals (items: xyz floats). */
SS_API ss_status ss_tessellation_normals(const ss_tessellation* tessellation, float* out_xyz, int32_t capacity,
                                         int32_t* out_count);
/** Triangles (items: 3 int32 vertex indices, counter-clockwise seen from the normal side). */
SS_API ss_status ss_tessellation_triangles(const ss_tessellation* tessellation, int32_t* out_indices,
                                           int32_t capacity, int32_t* out_count);
/** Moves the vertices to the limit surface of deformed control points (count = mesh vertices).
 *  Call `ss_picker_refit` on pickers of this tessellation afterwards. */
SS_API ss_status ss_tessellation_update(ss_tessellation* tessellation, const double* positions_xyz, int32_t count);

/** A picker (BVH) over the tessellation's triangles; keeps the tessellation alive. */
SS_API ss_status ss_picker_create(ss_tessellation* tessellation, ss_picker** out_picker);
SS_API void ss_picker_destroy(ss_picker* picker);
/** Follows the tessellation after `ss_tessellation_update`. */
SS_API ss_status ss_picker_refit(ss_picker* picker);
/** Nearest pick along the ray. `*out_hit` = 1 and `*out_pick` filled on a hit, 0 on a miss (both
 *  SS_OK). `refine` != 0 runs the Newton refinement on the limit surface. */
SS_API ss_status ss_picker_pick(const ss_picker* picker, const ss_ray* ray, int32_t refine, ss_pick* out_pick,
                                int32_t* out_hit);

/* ---------------------------------------------------------------------------------------------
 * Deformation requests and interaction helpers */

SS_API ss_status ss_request_create(ss_request** out_request);
SS_API void ss_request_destroy(ss_request* request);
SS_API ss_status ss_request_clear(ss_request* request);
/** Prescribes the displacement of control point `index` on the axes in `mask` (1 x, 2 y, 4 z). */
SS_API ss_status ss_request_add_vertex_constraint(ss_request* request, int32_t index, uint32_t mask,
                                                  const ss_vec3* displacement);
SS_API ss_status ss_request_add_force(ss_request* request, int32_t index, const ss_vec3* force);
/** A force at a limit point, spread with the limit weights (by the server). */
SS_API ss_status ss_request_add_surface_force(ss_request* request, const ss_surface_point* point,
                                              const ss_vec3* force);
/** Moves the limit point by `displacement`; `du_displacement` / `dv_displacement` (nullable)
 *  prescribe the change of its tangents. */
SS_API ss_status ss_request_add_limit_constraint(ss_request* request, const ss_surface_point* point,
                                                 const ss_vec3* displacement, const ss_vec3* du_displacement,
                                                 const ss_vec3* dv_displacement);
/** Per axis a: sum_j coefficients[j].a * u[indices[j]].a = values.a. */
SS_API ss_status ss_request_add_lagrange_constraint(ss_request* request, const int32_t* indices,
                                                    const ss_vec3* coefficients, int32_t count, const ss_vec3* values);
SS_API ss_status ss_request_set_surface_load(ss_request* request, const ss_vec3* load_per_area);
SS_API ss_status ss_request_set_pressure(ss_request* request, double pressure);
/** The mechanical model (PROTOCOL.md version 2, "The nonlinear model"). */
#define SS_MODEL_LINEAR 0     /* the linear Kirchhoff-Love shell (small displacements; the default) */
#define SS_MODEL_NONLINEAR 1  /* geometrically nonlinear: large displacements and rotations */
/** The model the request is solved with (SS_MODEL_*; a new or cleared request: SS_MODEL_LINEAR).
 *  For a hold: the hold state is solved with the nonlinear model while any live hold asks for
 *  it. A remote session sends a nonlinear request as JSON (the layout that carries the field). */
SS_API ss_status ss_request_set_model(ss_request* request, int32_t model);
SS_API ss_status ss_request_model(const ss_request* request, int32_t* out_model);
/** Holds every part of the tessellation's current shape that touches the plane (interaction.h,
 *  `floor_contact`). Outputs (nullable): the number of points constrained, and 1 if they alone
 *  fix every rigid-body motion. `options` NULL: defaults. */
SS_API ss_status ss_request_add_floor(ss_request* request, const ss_tessellation* tessellation,
                                      const ss_vec3* plane_point, const ss_vec3* plane_normal,
                                      const ss_floor_options* options, int32_t* out_points,
                                      int32_t* out_fixes_rigid_motion);
/** Numbers of entries, any output may be NULL. */
SS_API ss_status ss_request_counts(const ss_request* request, int32_t* out_vertex_constraints,
                                   int32_t* out_lagrange_constraints, int32_t* out_forces,
                                   int32_t* out_limit_constraints, int32_t* out_surface_forces);

/** Grabs the limit point `point` of the shape shown (`current_xyz` = deformed control points, or
 *  NULL / 0 for the rest shape) with a hand at `hand`. `options` NULL: defaults. */
SS_API ss_status ss_grab_begin(const ss_evaluator* evaluator, const ss_surface_point* point, const double* current_xyz,
                               int32_t count, const ss_pose* hand, const ss_grab_options* options, ss_grab** out_grab);
SS_API void ss_grab_destroy(ss_grab* grab);
/** Where the grabbed point belongs for the hand at `hand`. */
SS_API ss_status ss_grab_target(const ss_grab* grab, const ss_pose* hand, ss_vec3* out_target);
/** Adds the grab's limit constraint for the hand at `hand` to a request. */
SS_API ss_status ss_request_add_grab(ss_request* request, const ss_grab* grab, const ss_pose* hand);

/* ---------------------------------------------------------------------------------------------
 * Levels of detail */

/** `coarse` refined `levels` (1..6) times; same limit surface, coarse point i = fine point i. */
SS_API ss_status ss_refinement_create(const ss_mesh* coarse, int32_t levels, ss_refinement** out_refinement);
SS_API void ss_refinement_destroy(ss_refinement* refinement);
/** A new mesh handle with the fine control mesh (destroy it with ss_mesh_destroy). */
SS_API ss_status ss_refinement_fine_mesh(const ss_refinement* refinement, ss_mesh** out_mesh);
SS_API ss_status ss_refinement_fine_point(const ss_refinement* refinement, const ss_surface_point* coarse_point,
                                          ss_surface_point* out_fine_point);
/** x_f = S x_c for coarse control positions (items: xyz; out has the fine vertex count). */
SS_API ss_status ss_refinement_refine_positions(const ss_refinement* refinement, const double* coarse_xyz,
                                                int32_t count, double* out_fine_xyz, int32_t capacity,
                                                int32_t* out_count);
/** A new request for the fine mesh from one for the coarse mesh (SS_FORCE_TRANSFER_*). */
SS_API ss_status ss_refinement_request_to_fine(const ss_refinement* refinement, const ss_request* coarse_request,
                                               int32_t force_transfer, ss_request** out_fine_request);

/* ---------------------------------------------------------------------------------------------
 * Sessions: `ss_session_create_remote` (below) talks to a server over HTTP;
 * `ss_session_create_embedded` (softshell_embedded_c.h, in the server library) runs one in-process */

/** The host's threads (Box2D's enqueueTask, Jolt's JobSystem): where a session runs its
 *  background work (a remote session's asynchronous requests; an embedded server's
 *  precomputations and solves). `enqueue` runs `task(task_data)` soon, exactly once, on one of the
 *  host's threads; it is called from any thread, must not block waiting for the task and must not
 *  drop it. An embedded server's tasks never wait for other tasks, so a pool of any size makes
 *  progress; a remote session's tasks wait on the network (one request each), so do not share a
 *  small pool between a remote session and the in-process server it talks to. Blittable (24
 *  bytes on 64-bit platforms). */
typedef void (*ss_task_fn)(void* task_data);
typedef void (*ss_enqueue_task_fn)(ss_task_fn task, void* task_data, void* user_context);
typedef struct ss_task_system {
  ss_enqueue_task_fn enqueue;
  int32_t concurrency;  /* tasks the host runs at once, >= 1 */
  void* user_context;   /* passed to every enqueue */
} ss_task_system;

/** Options of a remote session. */
typedef struct ss_remote_options {
  int32_t connect_timeout_ms;  /* time to open a connection; 0: 5000 */
  int32_t request_timeout_ms;  /* time for one request (a deformation may wait for the server's
                                  precomputation); 0: 300000 */
  int32_t binary;              /* != 0: the paper's binary layouts where a body fits them (results in
                                  f32); 0 (default): JSON, double precision */
  int32_t async_threads;       /* threads running asynchronous deformations; 0: 2 */
  const char* auth_token;      /* access token of a server started with --auth-token-file, sent as
                                  `Authorization: Bearer <token>` on every request (copied in by
                                  ss_session_create_remote*); NULL or "": none. A server that wants
                                  one refuses requests without it (HTTP 401) with
                                  SS_INVALID_ARGUMENT, the message naming auth_token */
} ss_remote_options;
SS_API void ss_remote_options_default(ss_remote_options* out);
/** A session with the server at `url` (`http://host:port` or `host:port`) that answered
 *  `GET /health`; SS_UNAVAILABLE if it did not. `options` NULL: defaults. */
SS_API ss_status ss_session_create_remote(const char* url, const ss_remote_options* options,
                                          ss_session** out_session);
/** The same, with its asynchronous requests run as the host's tasks (`tasks` NULL: the session's
 *  own `async_threads`). The host must keep running tasks until the session is destroyed. */
SS_API ss_status ss_session_create_remote_on(const char* url, const ss_remote_options* options,
                                             const ss_task_system* tasks, ss_session** out_session);

SS_API void ss_session_destroy(ss_session* session);
/** 32 lowercase hex characters plus NUL into `out` (capacity >= 33 chars). */
SS_API ss_status ss_geom_id_to_hex(const ss_geom_id* id, char* out, int32_t capacity);
/** Uploads a mesh and material (`name_space` nullable = default). `*out_created` (nullable) = 1 for
 *  a new geometry, 0 if it existed. Blocks until the server answered (not for the precomputation). */
SS_API ss_status ss_session_upload(ss_session* session, const ss_mesh* mesh, const ss_material* material,
                                   const char* name_space, ss_geom_id* out_id, int32_t* out_created);
/** Deletes a geometry and everything kept for it: its results, holds and precomputed model
 *  (`DELETE /geometries/{id}`). Operations waiting on it end with SS_GONE; later calls for the id
 *  are SS_NOT_FOUND until the same content is uploaded again, whose result ids then continue
 *  after the deleted ones (asking for those is SS_GONE). SS_NOT_FOUND for an unknown geometry.
 *  Blocks for one request. */
SS_API ss_status ss_session_remove_geometry(ss_session* session, const ss_geom_id* id);
/** Solves and stores a deformation; blocks. Deformed control points (items: xyz; capacity must be
 *  at least the mesh's vertex count). */
SS_API ss_status ss_session_deform(ss_session* session, const ss_geom_id* id, const ss_request* request,
                                   uint32_t* out_res_id, double* out_xyz, int32_t capacity, int32_t* out_count);
/** Starts a deformation and returns at once. The request is copied. */
SS_API ss_status ss_session_deform_begin(ss_session* session, const ss_geom_id* id, const ss_request* request,
                                         ss_deformation** out_operation);
/** `*out_ready` = 1 once finished (successfully or not), else 0. Never blocks. */
SS_API ss_status ss_deformation_poll(ss_deformation* operation, int32_t* out_ready);
/** Waits up to `timeout_ms` (>= 0) for the operation; `*out_ready` as in poll. */
SS_API ss_status ss_deformation_wait(ss_deformation* operation, int32_t timeout_ms, int32_t* out_ready);
/** Copies the finished result out: SS_NOT_READY while running; the request's own error status if
 *  it failed (e.g. SS_UNPROCESSABLE for an undetermined system, message set). May be repeated. */
SS_API ss_status ss_deformation_read(ss_deformation* operation, uint32_t* out_res_id, double* out_xyz,
                                     int32_t capacity, int32_t* out_count);
/** How the finished deformation was solved: its model (SS_MODEL_*) and, for the nonlinear model,
 *  Newton's iterations and the final relative out-of-balance force (0 and 0 for the linear
 *  model). Any output may be NULL. Status and message as in ss_deformation_read. */
SS_API ss_status ss_deformation_read_model(ss_deformation* operation, int32_t* out_model, int32_t* out_iterations,
                                           double* out_residual);
/** Releases the operation; never blocks (a running request finishes in the background). A request
 *  still running when the process exits is finished first: exit waits for it (up to a minute). */
SS_API void ss_deformation_destroy(ss_deformation* operation);
/** The newest result if newer than `have`; otherwise waits up to `wait_ms` for one. `*out_has_new`
 *  = 1 and the outputs filled if there is one, 0 otherwise. */
SS_API ss_status ss_session_latest_result(ss_session* session, const ss_geom_id* id, uint32_t have, int32_t wait_ms,
                                          int32_t* out_has_new, uint32_t* out_res_id, double* out_xyz,
                                          int32_t capacity, int32_t* out_count);

/* ---------------------------------------------------------------------------------------------
 * Holds and events (PROTOCOL.md version 2): many clients acting on one object at once, and
 * results pushed to followers. Nothing here calls back into the host: puts are polled like
 * asynchronous deformations, subscriptions are polled once a frame. */

/** Starts creating hold `hold_id` (1 to 64 characters of [A-Za-z0-9._-]) on a geometry or
 *  replacing its contents with `request` (copied), with a lease of `ttl_ms` (1 .. 600000: without
 *  another put within it the hold lapses); returns at once. Putting the same contents again only
 *  renews the lease. */
SS_API ss_status ss_session_put_hold_begin(ss_session* session, const ss_geom_id* id, const char* hold_id,
                                           const ss_request* request, int32_t ttl_ms, ss_hold_put** out_operation);
/** `*out_ready` = 1 once answered (accepted or refused), else 0. Never blocks. */
SS_API ss_status ss_hold_put_poll(ss_hold_put* operation, int32_t* out_ready);
/** The answer: the first stored result that includes this version of the hold (deformed control
 *  points as in ss_session_deform) and `*out_version` (nullable), the hold's version it includes.
 *  SS_NOT_READY while running; the refusal's status and message otherwise: SS_CONFLICT (the hold
 *  contradicts other holds, which the message names), SS_UNPROCESSABLE (the hold state would be
 *  undetermined), SS_INVALID_ARGUMENT, SS_NOT_FOUND. May be repeated. */
SS_API ss_status ss_hold_put_read(ss_hold_put* operation, uint32_t* out_res_id, uint64_t* out_version,
                                  double* out_xyz, int32_t capacity, int32_t* out_count);
/** How the hold state of the answer was solved, as ss_deformation_read_model. */
SS_API ss_status ss_hold_put_read_model(ss_hold_put* operation, int32_t* out_model, int32_t* out_iterations,
                                        double* out_residual);
/** Releases the operation; never blocks (a running put finishes in the background, and before
 *  the process exits, as a deformation's). */
SS_API void ss_hold_put_destroy(ss_hold_put* operation);
/** Releases the hold and waits for the first result without it (`*out_res_id`, nullable).
 *  SS_NOT_FOUND for an unknown hold; SS_CONFLICT when the remaining holds cannot be solved (the
 *  hold is released all the same). Blocks for one request. */
SS_API ss_status ss_session_release_hold(ss_session* session, const ss_geom_id* id, const char* hold_id,
                                         uint32_t* out_res_id);

#define SS_FEED_CONNECTING 0  /* not receiving: a remote stream (re)connecting by itself */
#define SS_FEED_LIVE 1        /* receiving results as they are stored */
#define SS_FEED_FAILED 2      /* ended for good (the geometry is unknown); poll returns why */

/** Follows a geometry's results: the newest one with an id above `after` at once, then each newly
 *  stored one; a remote session reconnects by itself (Last-Event-ID). Blocks until the server
 *  answered the stream (SS_NOT_FOUND for an unknown geometry). */
SS_API ss_status ss_session_subscribe(ss_session* session, const ss_geom_id* id, uint32_t after,
                                      ss_subscription** out_subscription);
/** The newest result not taken yet (latest wins: a slow reader skips to the newest):
 *  `*out_has_new` = 1 and the outputs filled, or 0. Never blocks. A result that does not fit
 *  `capacity` (SS_BUFFER_TOO_SMALL) is kept for the next call. SS_FEED_FAILED's error once
 *  nothing is left to take. */
SS_API ss_status ss_subscription_poll(ss_subscription* subscription, int32_t* out_has_new, uint32_t* out_res_id,
                                      double* out_xyz, int32_t capacity, int32_t* out_count);
/** `*out_state` = SS_FEED_*. */
SS_API ss_status ss_subscription_state(ss_subscription* subscription, int32_t* out_state);
/** Stops following (a remote stream is closed; returns promptly). */
SS_API void ss_subscription_destroy(ss_subscription* subscription);

#define SS_GEOMETRY_PRECOMPUTING 0  /* the server is assembling and factorizing its stiffness */
#define SS_GEOMETRY_READY 1         /* deformations are solved at once */
#define SS_GEOMETRY_FAILED 2        /* the precomputation failed; deformations return its error */

/** What the server knows about a geometry. */
typedef struct ss_geometry_status {
  int32_t status;        /* SS_GEOMETRY_* */
  int32_t num_vertices;
  int32_t num_faces;
  uint32_t num_results;  /* stored results */
  double progress;       /* precomputation progress in [0, 1] (1 once ready) */
} ss_geometry_status;

/** Status and precomputation progress of an uploaded geometry, for a loading bar: poll it instead
 *  of blocking in a deformation. `out_error` (nullable, `error_capacity` chars) receives why the
 *  precomputation failed ("" otherwise), truncated to fit and NUL-terminated. SS_NOT_FOUND for an
 *  unknown id. */
SS_API ss_status ss_session_geometry_status(ss_session* session, const ss_geom_id* id, ss_geometry_status* out_status,
                                            char* out_error, int32_t error_capacity);
/** The limit point at `point` and its tangents as combinations of the control points, computed
 *  by the server (`GET .../limit_comb`): indices and the weights of position, du and dv, as
 *  `ss_evaluator_stencil` (the weight buffers may be NULL). */
SS_API ss_status ss_session_limit_comb(ss_session* session, const ss_geom_id* id, const ss_surface_point* point,
                                       int32_t* out_indices, double* out_position, double* out_du, double* out_dv,
                                       int32_t capacity, int32_t* out_count);

/* ---------------------------------------------------------------------------------------------
 * Stresses of a stored result (softshell/stresses.h; HTTP `.../results/{res_id}/stresses`) */

/** The stress state at one surface point, in a local Cartesian frame: e1 along the limit
 *  surface's u tangent, e2 in the tangent plane, e3 the unit normal. */
typedef struct ss_stress_sample {
  ss_surface_point point;
  ss_vec3 position;         /* rest limit position */
  ss_vec3 membrane_force;   /* n11, n22, n12 (N/m) */
  ss_vec3 bending_moment;   /* m11, m22, m12 (N m / m) */
  double von_mises_top;     /* Pa, at +t/2 along the normal */
  double von_mises_bottom;  /* Pa, at -t/2 */
} ss_stress_sample;

/** Computes the stresses of result `res_id` of geometry `id` (one call to the server) at the
 *  vertices of the level-`level` tessellation (1..4, in the order of `ss_tessellation_vertices` of
 *  a level-`level` tessellation of the same mesh: what a renderer of that level draws), or, with
 *  `level` 0, at `points` (`num_points` of them, 1..1,000,000). `yield_strength` (Pa, >= 0; 0 =
 *  unknown) flags where the material yields: the linear elastic model stops holding there (a
 *  preset's yield strength: `ss_material_preset_at`). SS_NOT_FOUND for an unknown
 *  geometry or result. Read the field with the two functions below; destroy it when done. */
SS_API ss_status ss_session_stresses(ss_session* session, const ss_geom_id* id, uint32_t res_id, int32_t level,
                                     const ss_surface_point* points, int32_t num_points, double yield_strength,
                                     ss_stress_field** out_field);
/** The samples, one per queried point, in order (the buffer convention above). */
SS_API ss_status ss_stress_field_samples(const ss_stress_field* field, ss_stress_sample* out_samples,
                                         int32_t capacity, int32_t* out_count);
/** The largest von Mises stress over the whole surface (its quadrature points), where it is, and
 *  `*out_exceeds_yield` (nullable) = 1 if it exceeds the query's yield strength. */
SS_API ss_status ss_stress_field_max(const ss_stress_field* field, ss_stress_sample* out_max,
                                     int32_t* out_exceeds_yield);
SS_API void ss_stress_field_destroy(ss_stress_field* field);

#ifdef __cplusplus
}  /* extern "C" */
#endif

#endif /* SOFTSHELL_C_H */
