// The C ABI (softshell_c.h) over the C++ SDK. Every entry point runs its body under `guard`, which
// turns every exception into a status code and a thread-local message; nothing throws across.

#include "softshell/softshell_c.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <future>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/deformation.h"
#include "softshell/interaction.h"
#include "softshell/level_of_detail.h"
#include "softshell/limit_evaluator.h"
#include "softshell/mesh_validation.h"
#include "softshell/obj_io.h"
#include "softshell/picking.h"
#include "softshell/remote_session.h"
#include "softshell/session.h"
#include "softshell/softshell_c_bridge.h"
#include "softshell/tessellation.h"

using softshell::ErrorCode;
using softshell::Vec3;

// The layouts that C, C# (P/Invoke, sequential layout) and Unreal rely on. Changing one is an ABI
// break: bump SS_ABI_VERSION.
static_assert(SS_ABI_VERSION == 1u);
static_assert(sizeof(ss_vec3) == 24 && sizeof(ss_quat) == 32 && sizeof(ss_pose) == 56);
static_assert(sizeof(ss_surface_point) == 24 && offsetof(ss_surface_point, u) == 8);
static_assert(sizeof(ss_material) == 32 && sizeof(ss_geom_id) == 16);
static_assert(sizeof(ss_ray) == 64 && offsetof(ss_ray, t_min) == 48);
static_assert(sizeof(ss_limit_sample) == 96);
static_assert(sizeof(ss_pick) == 184 && offsetof(ss_pick, estimate) == 8 && offsetof(ss_pick, t) == 152 &&
              offsetof(ss_pick, iterations) == 176);
static_assert(sizeof(ss_grab_options) == 8 && sizeof(ss_floor_options) == 16);

// ------------------------------------------------------------------------------------------------
// Handles: a tag checked on every call, then the C++ object.

namespace {
enum Tag : uint32_t {
  kMeshTag = 0x53534d31,
  kEvaluatorTag,
  kTessellationTag,
  kPickerTag,
  kRequestTag,
  kGrabTag,
  kRefinementTag,
  kSessionTag,
  kDeformationTag,
  kDeadTag = 0xdeadbeef,
};
}  // namespace

struct ss_mesh {
  uint32_t tag = kMeshTag;
  softshell::ControlMesh mesh;
};
struct ss_evaluator {
  uint32_t tag = kEvaluatorTag;
  softshell::LimitEvaluator evaluator;
};
struct ss_tessellation {
  uint32_t tag = kTessellationTag;
  std::shared_ptr<softshell::Tessellation> tessellation;
};
struct ss_picker {
  uint32_t tag = kPickerTag;
  std::shared_ptr<softshell::Tessellation> tessellation;  // keeps the picker's reference valid
  softshell::Picker picker;
};
struct ss_request {
  uint32_t tag = kRequestTag;
  softshell::DeformationRequest request;
};
struct ss_grab {
  uint32_t tag = kGrabTag;
  softshell::Grab grab;
};
struct ss_refinement {
  uint32_t tag = kRefinementTag;
  softshell::MeshRefinement refinement;
};
struct ss_session {
  uint32_t tag = kSessionTag;
  std::shared_ptr<softshell::Session> session;
};
struct ss_deformation {
  uint32_t tag = kDeformationTag;
  std::shared_ptr<softshell::Session> session;  // alive while the request runs
  std::shared_future<softshell::Result<softshell::DeformationResult>> future;
};

namespace {

using softshell::fail;

thread_local std::string g_message;  // NOLINT(cppcoreguidelines-avoid-non-const-global-variables)

// A status that exists only in the C ABI (SS_BUFFER_TOO_SMALL, SS_NOT_READY).
struct CStatus {
  ss_status status;
  std::string message;
};

const char* kind_name(uint32_t tag) {
  switch (tag) {
    case kMeshTag: return "ss_mesh";
    case kEvaluatorTag: return "ss_evaluator";
    case kTessellationTag: return "ss_tessellation";
    case kPickerTag: return "ss_picker";
    case kRequestTag: return "ss_request";
    case kGrabTag: return "ss_grab";
    case kRefinementTag: return "ss_refinement";
    case kSessionTag: return "ss_session";
    case kDeformationTag: return "ss_deformation";
    default: return "handle";
  }
}

template <class H>
H& live(H* handle, uint32_t tag, const char* argument) {
  if (handle == nullptr) fail(ErrorCode::kInvalidArgument, std::string(argument) + " is NULL");
  if (handle->tag != tag) {
    fail(ErrorCode::kInvalidArgument, std::string(argument) + " is not a live " + kind_name(tag) +
                                          (handle->tag == kDeadTag ? " (it was destroyed)" : ""));
  }
  return *handle;
}

template <class H>
void destroy(H* handle, uint32_t tag) noexcept {
  if (handle == nullptr || handle->tag != tag) return;  // NULL, or not ours: nothing to release
  handle->tag = kDeadTag;
  delete handle;
}

template <class T>
T* required(T* p, const char* argument) {
  if (p == nullptr) fail(ErrorCode::kInvalidArgument, std::string(argument) + " is NULL");
  return p;
}

int32_t count_arg(int32_t n, const char* argument) {
  if (n < 0) fail(ErrorCode::kInvalidArgument, std::string(argument) + " must not be negative");
  return n;
}

Vec3 vec(const ss_vec3* v, const char* argument) {
  required(v, argument);
  const Vec3 out(v->x, v->y, v->z);
  if (!out.allFinite()) fail(ErrorCode::kInvalidArgument, std::string(argument) + " is not finite");
  return out;
}

ss_vec3 to_c(const Vec3& v) { return ss_vec3{v.x(), v.y(), v.z()}; }

softshell::SurfacePoint point(const ss_surface_point* p, const char* argument) {
  required(p, argument);
  return softshell::SurfacePoint{p->face, p->subface, p->u, p->v};
}

ss_surface_point to_c(const softshell::SurfacePoint& p) { return ss_surface_point{p.face, p.subface, p.u, p.v}; }

softshell::Pose pose(const ss_pose* p, const char* argument) {
  required(p, argument);
  softshell::Pose out;
  out.position = Vec3(p->position.x, p->position.y, p->position.z);
  out.orientation = Eigen::Quaterniond(p->orientation.w, p->orientation.x, p->orientation.y, p->orientation.z);
  if (!out.position.allFinite() || !out.orientation.coeffs().allFinite() || out.orientation.coeffs().isZero(0.0)) {
    fail(ErrorCode::kInvalidArgument, std::string(argument) + " must be finite with a non-zero orientation");
  }
  return out;
}

// `count` xyz triples from `xyz` (which may be NULL only for count 0), finite.
std::vector<Vec3> read_xyz(const double* xyz, int32_t count, const char* argument) {
  count_arg(count, "count");
  if (count > 0) required(xyz, argument);
  std::vector<Vec3> out(static_cast<size_t>(count));
  for (size_t i = 0; i < out.size(); ++i) {
    out[i] = Vec3(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    if (!out[i].allFinite()) {
      fail(ErrorCode::kInvalidArgument, std::string(argument) + ": point " + std::to_string(i) + " is not finite");
    }
  }
  return out;
}

// The buffer convention: always report the count; NULL/0 asks only for it; too small writes nothing.
template <class T, class Fill>
void write_items(T* out, int32_t capacity, int32_t* out_count, size_t items, const char* what, Fill&& fill) {
  required(out_count, "out_count");
  count_arg(capacity, "capacity");
  if (items > static_cast<size_t>(std::numeric_limits<int32_t>::max())) {
    fail(ErrorCode::kResourceExhausted, std::string(what) + ": too many items for an int32 count");
  }
  *out_count = static_cast<int32_t>(items);
  if (out == nullptr) {
    if (capacity == 0) return;  // size query
    fail(ErrorCode::kInvalidArgument, std::string(what) + ": the output buffer is NULL but capacity is " +
                                          std::to_string(capacity));
  }
  if (static_cast<size_t>(capacity) < items) {
    throw CStatus{SS_BUFFER_TOO_SMALL, std::string(what) + ": needs " + std::to_string(items) +
                                           " items, the buffer holds " + std::to_string(capacity)};
  }
  fill(out);
}

void write_xyz(const std::vector<Vec3>& points, double* out, int32_t capacity, int32_t* out_count, const char* what) {
  write_items(out, capacity, out_count, points.size(), what, [&](double* o) {
    for (size_t i = 0; i < points.size(); ++i) {
      o[3 * i] = points[i].x();
      o[3 * i + 1] = points[i].y();
      o[3 * i + 2] = points[i].z();
    }
  });
}

void write_xyz_f(const std::vector<Vec3>& points, float* out, int32_t capacity, int32_t* out_count, const char* what) {
  write_items(out, capacity, out_count, points.size(), what, [&](float* o) {
    for (size_t i = 0; i < points.size(); ++i) {
      o[3 * i] = static_cast<float>(points[i].x());
      o[3 * i + 1] = static_cast<float>(points[i].y());
      o[3 * i + 2] = static_cast<float>(points[i].z());
    }
  });
}

softshell::GeomId geom_id(const ss_geom_id* id) {
  required(id, "id");
  softshell::GeomId out;
  std::memcpy(out.bytes.data(), id->bytes, 16);
  return out;
}

// Operations destroyed while running: kept (with their session) until they finish, so that
// `ss_deformation_destroy` never blocks and no request is abandoned mid-flight.
class Reaper {
 public:
  void adopt(std::shared_ptr<softshell::Session> session,
             std::shared_future<softshell::Result<softshell::DeformationResult>> future) {
    std::lock_guard lock(mutex_);
    purge();
    orphans_.push_back(Orphan{std::move(session), std::move(future)});
  }
  void purge_finished() {
    std::lock_guard lock(mutex_);
    purge();
  }

 private:
  struct Orphan {
    std::shared_ptr<softshell::Session> session;  // destroyed after the future (reverse order)
    std::shared_future<softshell::Result<softshell::DeformationResult>> future;
  };
  void purge() {
    std::erase_if(orphans_, [](const Orphan& o) {
      return o.future.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
    });
  }
  std::mutex mutex_;
  std::vector<Orphan> orphans_;
};

Reaper& reaper() {
  static Reaper r;
  return r;
}

bool ready(const ss_deformation& op) {
  return op.future.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
}

}  // namespace

namespace softshell::c_api {

ss_status guard(const char* function, const std::function<void()>& fn) noexcept {
  try {
    try {
      fn();
      g_message.clear();
      return SS_OK;
    } catch (const CStatus& s) {
      g_message = std::string(function) + ": " + s.message;
      return s.status;
    } catch (const Exception& e) {
      g_message = std::string(function) + ": " + e.what();
      return static_cast<ss_status>(e.code());
    } catch (const std::bad_alloc&) {
      g_message = std::string(function) + ": out of memory";
      return SS_RESOURCE_EXHAUSTED;
    } catch (const std::exception& e) {
      g_message = std::string(function) + ": internal error: " + e.what();
      return SS_INTERNAL;
    } catch (...) {
      g_message = std::string(function) + ": internal error (unknown exception)";
      return SS_INTERNAL;
    }
  } catch (...) {
    // Even storing the message failed (out of memory).
    return SS_RESOURCE_EXHAUSTED;
  }
}

ss_session* wrap_session(std::shared_ptr<Session> session) {
  if (!session) fail(ErrorCode::kInvalidArgument, "wrap_session: the session is null");
  auto* handle = new ss_session;
  handle->session = std::move(session);
  return handle;
}

std::shared_ptr<Session> session_of(const ss_session* handle) {
  return live(handle, kSessionTag, "session").session;
}

}  // namespace softshell::c_api

using softshell::c_api::guard;

// ------------------------------------------------------------------------------------------------
// Version and status

extern "C" {

uint32_t ss_abi_version(void) { return SS_ABI_VERSION; }

const char* ss_last_error_message(void) { return g_message.c_str(); }

const char* ss_status_name(ss_status status) {
  switch (status) {
    case SS_OK: return "ok";
    case SS_INVALID_ARGUMENT: return "invalid_argument";
    case SS_UNPROCESSABLE: return "unprocessable";
    case SS_NOT_FOUND: return "not_found";
    case SS_PAYLOAD_TOO_LARGE: return "payload_too_large";
    case SS_UNSUPPORTED_MEDIA_TYPE: return "unsupported_media_type";
    case SS_NOT_ACCEPTABLE: return "not_acceptable";
    case SS_RESOURCE_EXHAUSTED: return "resource_exhausted";
    case SS_UNAVAILABLE: return "unavailable";
    case SS_CANCELLED: return "cancelled";
    case SS_IO_ERROR: return "io_error";
    case SS_INTERNAL: return "internal";
    case SS_CONFLICT: return "conflict";
    case SS_BUFFER_TOO_SMALL: return "buffer_too_small";
    case SS_NOT_READY: return "not_ready";
    default: return "unknown_status";
  }
}

void ss_grab_options_default(ss_grab_options* out) {
  if (out) *out = ss_grab_options{1, 0};
}

void ss_floor_options_default(ss_floor_options* out) {
  if (out) *out = ss_floor_options{-1.0, 0, 0};
}

// ------------------------------------------------------------------------------------------------
// Control mesh

ss_status ss_mesh_create(const double* positions_xyz, int32_t num_vertices, const int32_t* face_sizes,
                         int32_t num_faces, const int32_t* face_indices, int32_t num_face_indices,
                         ss_mesh** out_mesh) {
  return guard("ss_mesh_create", [&] {
    required(out_mesh, "out_mesh");
    *out_mesh = nullptr;
    std::vector<Vec3> positions = read_xyz(positions_xyz, num_vertices, "positions_xyz");
    count_arg(num_faces, "num_faces");
    count_arg(num_face_indices, "num_face_indices");
    if (num_faces > 0) required(face_sizes, "face_sizes");
    if (num_face_indices > 0) required(face_indices, "face_indices");
    int64_t total = 0;
    for (int32_t f = 0; f < num_faces; ++f) {
      if (face_sizes[f] < 3) {
        fail(ErrorCode::kInvalidArgument, "face " + std::to_string(f) + " has " + std::to_string(face_sizes[f]) +
                                              " corners; a face needs at least 3");
      }
      total += face_sizes[f];
    }
    if (total != num_face_indices) {
      fail(ErrorCode::kInvalidArgument, "the face sizes add up to " + std::to_string(total) + " but " +
                                            std::to_string(num_face_indices) + " face indices were given");
    }
    for (int32_t k = 0; k < num_face_indices; ++k) {
      if (face_indices[k] < 0 || face_indices[k] >= num_vertices) {
        fail(ErrorCode::kInvalidArgument, "face index " + std::to_string(k) + " is " + std::to_string(face_indices[k]) +
                                              ", out of range (" + std::to_string(num_vertices) + " vertices)");
      }
    }
    auto handle = std::make_unique<ss_mesh>();
    handle->mesh = softshell::ControlMesh(std::move(positions), std::vector<int32_t>(face_sizes, face_sizes + num_faces),
                                          std::vector<int32_t>(face_indices, face_indices + num_face_indices));
    *out_mesh = handle.release();
  });
}

ss_status ss_mesh_read_obj(const char* path, ss_mesh** out_mesh) {
  return guard("ss_mesh_read_obj", [&] {
    required(out_mesh, "out_mesh");
    *out_mesh = nullptr;
    required(path, "path");
    auto handle = std::make_unique<ss_mesh>();
    handle->mesh = softshell::read_obj(path).value();
    *out_mesh = handle.release();
  });
}

ss_status ss_mesh_write_obj(const ss_mesh* mesh, const char* path) {
  return guard("ss_mesh_write_obj", [&] {
    const auto& m = live(mesh, kMeshTag, "mesh");
    required(path, "path");
    softshell::write_obj(m.mesh, path).value();
  });
}

void ss_mesh_destroy(ss_mesh* mesh) { destroy(mesh, kMeshTag); }

ss_status ss_mesh_counts(const ss_mesh* mesh, int32_t* out_num_vertices, int32_t* out_num_faces) {
  return guard("ss_mesh_counts", [&] {
    const auto& m = live(mesh, kMeshTag, "mesh");
    if (out_num_vertices) *out_num_vertices = m.mesh.num_vertices();
    if (out_num_faces) *out_num_faces = m.mesh.num_faces();
  });
}

ss_status ss_mesh_positions(const ss_mesh* mesh, double* out_xyz, int32_t capacity, int32_t* out_count) {
  return guard("ss_mesh_positions", [&] {
    write_xyz(live(mesh, kMeshTag, "mesh").mesh.positions(), out_xyz, capacity, out_count, "positions");
  });
}

ss_status ss_mesh_set_positions(ss_mesh* mesh, const double* positions_xyz, int32_t count) {
  return guard("ss_mesh_set_positions", [&] {
    auto& m = live(mesh, kMeshTag, "mesh");
    std::vector<Vec3> p = read_xyz(positions_xyz, count, "positions_xyz");
    if (count != m.mesh.num_vertices()) {
      fail(ErrorCode::kInvalidArgument, "expected " + std::to_string(m.mesh.num_vertices()) + " positions, got " +
                                            std::to_string(count));
    }
    m.mesh.positions() = std::move(p);
  });
}

ss_status ss_mesh_faces(const ss_mesh* mesh, int32_t* out_sizes, int32_t sizes_capacity, int32_t* out_num_faces,
                        int32_t* out_indices, int32_t indices_capacity, int32_t* out_num_indices) {
  return guard("ss_mesh_faces", [&] {
    const auto& m = live(mesh, kMeshTag, "mesh").mesh;
    required(out_num_faces, "out_num_faces");
    required(out_num_indices, "out_num_indices");
    count_arg(sizes_capacity, "sizes_capacity");
    count_arg(indices_capacity, "indices_capacity");
    const std::vector<int32_t> sizes = m.face_sizes();
    *out_num_faces = m.num_faces();
    *out_num_indices = static_cast<int32_t>(m.face_indices().size());
    // Check both before writing either.
    const bool query_sizes = out_sizes == nullptr && sizes_capacity == 0;
    const bool query_indices = out_indices == nullptr && indices_capacity == 0;
    if ((!query_sizes && sizes_capacity < *out_num_faces) || (!query_indices && indices_capacity < *out_num_indices)) {
      throw CStatus{SS_BUFFER_TOO_SMALL, "needs " + std::to_string(*out_num_faces) + " face sizes and " +
                                             std::to_string(*out_num_indices) + " face indices"};
    }
    int32_t n = 0;
    write_items(out_sizes, sizes_capacity, &n, sizes.size(), "face sizes",
                [&](int32_t* o) { std::copy(sizes.begin(), sizes.end(), o); });
    write_items(out_indices, indices_capacity, &n, m.face_indices().size(), "face indices",
                [&](int32_t* o) { std::copy(m.face_indices().begin(), m.face_indices().end(), o); });
  });
}

ss_status ss_mesh_set_boundary(ss_mesh* mesh, int32_t boundary) {
  return guard("ss_mesh_set_boundary", [&] {
    auto& m = live(mesh, kMeshTag, "mesh");
    if (boundary != SS_BOUNDARY_EDGE_AND_CORNER && boundary != SS_BOUNDARY_NONE) {
      fail(ErrorCode::kInvalidArgument, "boundary must be SS_BOUNDARY_EDGE_AND_CORNER (0) or SS_BOUNDARY_NONE (1)");
    }
    m.mesh.set_boundary(boundary == SS_BOUNDARY_NONE ? softshell::BoundaryMode::kNone
                                                     : softshell::BoundaryMode::kEdgeAndCorner);
  });
}

ss_status ss_mesh_add_crease(ss_mesh* mesh, int32_t v0, int32_t v1, float sharpness) {
  return guard("ss_mesh_add_crease", [&] {
    auto& m = live(mesh, kMeshTag, "mesh");
    const int32_t n = m.mesh.num_vertices();
    if (v0 < 0 || v0 >= n || v1 < 0 || v1 >= n || v0 == v1) {
      fail(ErrorCode::kInvalidArgument, "a crease needs two different control points in 0.." + std::to_string(n - 1));
    }
    if (!std::isfinite(sharpness) || sharpness < 0.0f) {
      fail(ErrorCode::kInvalidArgument, "crease sharpness must be finite and >= 0");
    }
    m.mesh.creases().push_back(softshell::Crease{v0, v1, sharpness});
  });
}

ss_status ss_mesh_validate(const ss_mesh* mesh) {
  return guard("ss_mesh_validate", [&] { softshell::validate_mesh(live(mesh, kMeshTag, "mesh").mesh).value(); });
}

// ------------------------------------------------------------------------------------------------
// Limit surface

ss_status ss_evaluator_create(const ss_mesh* mesh, ss_evaluator** out_evaluator) {
  return guard("ss_evaluator_create", [&] {
    required(out_evaluator, "out_evaluator");
    *out_evaluator = nullptr;
    const auto& m = live(mesh, kMeshTag, "mesh");
    *out_evaluator = new ss_evaluator{kEvaluatorTag, softshell::LimitEvaluator::create(m.mesh).value()};
  });
}

void ss_evaluator_destroy(ss_evaluator* evaluator) { destroy(evaluator, kEvaluatorTag); }

ss_status ss_evaluator_num_subfaces(const ss_evaluator* evaluator, int32_t face, int32_t* out_count) {
  return guard("ss_evaluator_num_subfaces", [&] {
    const auto& ev = live(evaluator, kEvaluatorTag, "evaluator").evaluator;
    required(out_count, "out_count");
    if (face < 0 || face >= ev.num_faces()) {
      fail(ErrorCode::kInvalidArgument, "face " + std::to_string(face) + " is out of range (" +
                                            std::to_string(ev.num_faces()) + " faces)");
    }
    *out_count = ev.num_subfaces(face);
  });
}

ss_status ss_evaluator_evaluate(const ss_evaluator* evaluator, const ss_surface_point* p, const double* positions_xyz,
                                int32_t count, ss_limit_sample* out_sample) {
  return guard("ss_evaluator_evaluate", [&] {
    const auto& ev = live(evaluator, kEvaluatorTag, "evaluator").evaluator;
    required(out_sample, "out_sample");
    const softshell::SurfacePoint sp = point(p, "point");
    ev.check(sp).value();
    softshell::LimitSample s;
    if (positions_xyz == nullptr && count == 0) {
      s = ev.evaluate(sp);
    } else {
      s = ev.evaluate(sp, read_xyz(positions_xyz, count, "positions_xyz"));
    }
    *out_sample = ss_limit_sample{to_c(s.position), to_c(s.du), to_c(s.dv), to_c(s.normal())};
  });
}

ss_status ss_evaluator_stencil(const ss_evaluator* evaluator, const ss_surface_point* p, int32_t* out_indices,
                               double* out_position, double* out_du, double* out_dv, int32_t capacity,
                               int32_t* out_count) {
  return guard("ss_evaluator_stencil", [&] {
    const auto& ev = live(evaluator, kEvaluatorTag, "evaluator").evaluator;
    const softshell::LimitStencil st = ev.stencil(point(p, "point"));
    write_items(out_indices, capacity, out_count, st.size(), "stencil", [&](int32_t* o) {
      std::copy(st.indices.begin(), st.indices.end(), o);
      if (out_position) std::copy(st.position.begin(), st.position.end(), out_position);
      if (out_du) std::copy(st.du.begin(), st.du.end(), out_du);
      if (out_dv) std::copy(st.dv.begin(), st.dv.end(), out_dv);
    });
  });
}

// ------------------------------------------------------------------------------------------------
// Tessellation and picking

ss_status ss_tessellation_create(const ss_evaluator* evaluator, int32_t level, ss_tessellation** out) {
  return guard("ss_tessellation_create", [&] {
    required(out, "out");
    *out = nullptr;
    const auto& ev = live(evaluator, kEvaluatorTag, "evaluator").evaluator;
    auto t = std::make_shared<softshell::Tessellation>(softshell::Tessellation::create(ev, level).value());
    *out = new ss_tessellation{kTessellationTag, std::move(t)};
  });
}

void ss_tessellation_destroy(ss_tessellation* tessellation) { destroy(tessellation, kTessellationTag); }

ss_status ss_tessellation_counts(const ss_tessellation* tessellation, int32_t* out_num_vertices,
                                 int32_t* out_num_triangles) {
  return guard("ss_tessellation_counts", [&] {
    const auto& t = *live(tessellation, kTessellationTag, "tessellation").tessellation;
    if (out_num_vertices) *out_num_vertices = static_cast<int32_t>(t.vertices().size());
    if (out_num_triangles) *out_num_triangles = static_cast<int32_t>(t.triangles().size());
  });
}

ss_status ss_tessellation_vertices(const ss_tessellation* tessellation, float* out_xyz, int32_t capacity,
                                   int32_t* out_count) {
  return guard("ss_tessellation_vertices", [&] {
    write_xyz_f(live(tessellation, kTessellationTag, "tessellation").tessellation->vertices(), out_xyz, capacity,
                out_count, "vertices");
  });
}

ss_status ss_tessellation_normals(const ss_tessellation* tessellation, float* out_xyz, int32_t capacity,
                                  int32_t* out_count) {
  return guard("ss_tessellation_normals", [&] {
    write_xyz_f(live(tessellation, kTessellationTag, "tessellation").tessellation->normals(), out_xyz, capacity,
                out_count, "normals");
  });
}

ss_status ss_tessellation_triangles(const ss_tessellation* tessellation, int32_t* out_indices, int32_t capacity,
                                    int32_t* out_count) {
  return guard("ss_tessellation_triangles", [&] {
    const auto& tris = live(tessellation, kTessellationTag, "tessellation").tessellation->triangles();
    write_items(out_indices, capacity, out_count, tris.size(), "triangles", [&](int32_t* o) {
      for (size_t i = 0; i < tris.size(); ++i) std::copy(tris[i].begin(), tris[i].end(), o + 3 * i);
    });
  });
}

ss_status ss_tessellation_update(ss_tessellation* tessellation, const double* positions_xyz, int32_t count) {
  return guard("ss_tessellation_update", [&] {
    auto& t = *live(tessellation, kTessellationTag, "tessellation").tessellation;
    std::vector<Vec3> p = read_xyz(positions_xyz, count, "positions_xyz");
    t.update(p);
  });
}

ss_status ss_picker_create(ss_tessellation* tessellation, ss_picker** out_picker) {
  return guard("ss_picker_create", [&] {
    required(out_picker, "out_picker");
    *out_picker = nullptr;
    auto t = live(tessellation, kTessellationTag, "tessellation").tessellation;
    softshell::Picker picker = softshell::Picker::create(*t).value();
    *out_picker = new ss_picker{kPickerTag, std::move(t), std::move(picker)};
  });
}

void ss_picker_destroy(ss_picker* picker) { destroy(picker, kPickerTag); }

ss_status ss_picker_refit(ss_picker* picker) {
  return guard("ss_picker_refit", [&] { live(picker, kPickerTag, "picker").picker.refit().value(); });
}

ss_status ss_picker_pick(const ss_picker* picker, const ss_ray* ray, int32_t refine, ss_pick* out_pick,
                         int32_t* out_hit) {
  return guard("ss_picker_pick", [&] {
    const auto& p = live(picker, kPickerTag, "picker").picker;
    required(ray, "ray");
    required(out_pick, "out_pick");
    required(out_hit, "out_hit");
    *out_hit = 0;
    softshell::Ray r;
    r.origin = Vec3(ray->origin.x, ray->origin.y, ray->origin.z);
    r.direction = Vec3(ray->direction.x, ray->direction.y, ray->direction.z);
    r.t_min = ray->t_min;
    r.t_max = ray->t_max;
    softshell::PickOptions options;
    options.refine = refine != 0;
    const auto pick = p.pick(r, options).value();
    if (!pick) return;
    *out_hit = 1;
    ss_pick& o = *out_pick;
    o.triangle = pick->hit.triangle;
    o.status = static_cast<int32_t>(pick->status);
    o.estimate = to_c(pick->estimate);
    o.point = to_c(pick->point);
    o.position = to_c(pick->position);
    o.normal = to_c(pick->normal);
    o.du = to_c(pick->du);
    o.dv = to_c(pick->dv);
    o.t = pick->t;
    o.distance_to_ray = pick->distance_to_ray;
    o.triangle_t = pick->hit.t;
    o.iterations = pick->iterations;
    o.face_crossings = pick->face_crossings;
  });
}

// ------------------------------------------------------------------------------------------------
// Requests and interaction helpers

ss_status ss_request_create(ss_request** out_request) {
  return guard("ss_request_create", [&] {
    required(out_request, "out_request");
    *out_request = new ss_request;
  });
}

void ss_request_destroy(ss_request* request) { destroy(request, kRequestTag); }

ss_status ss_request_clear(ss_request* request) {
  return guard("ss_request_clear", [&] { live(request, kRequestTag, "request").request = {}; });
}

ss_status ss_request_add_vertex_constraint(ss_request* request, int32_t index, uint32_t mask,
                                           const ss_vec3* displacement) {
  return guard("ss_request_add_vertex_constraint", [&] {
    auto& r = live(request, kRequestTag, "request").request;
    if (index < 0) fail(ErrorCode::kInvalidArgument, "control point index must not be negative");
    if (mask == 0 || mask > 7) fail(ErrorCode::kInvalidArgument, "mask must be 1..7 (1 = x, 2 = y, 4 = z)");
    r.vertex_constraints.push_back({index, mask, vec(displacement, "displacement")});
  });
}

ss_status ss_request_add_force(ss_request* request, int32_t index, const ss_vec3* force) {
  return guard("ss_request_add_force", [&] {
    auto& r = live(request, kRequestTag, "request").request;
    if (index < 0) fail(ErrorCode::kInvalidArgument, "control point index must not be negative");
    r.forces.push_back({index, vec(force, "force")});
  });
}

ss_status ss_request_add_surface_force(ss_request* request, const ss_surface_point* p, const ss_vec3* force) {
  return guard("ss_request_add_surface_force", [&] {
    auto& r = live(request, kRequestTag, "request").request;
    r.surface_forces.push_back({point(p, "point"), vec(force, "force")});
  });
}

ss_status ss_request_add_limit_constraint(ss_request* request, const ss_surface_point* p, const ss_vec3* displacement,
                                          const ss_vec3* du_displacement, const ss_vec3* dv_displacement) {
  return guard("ss_request_add_limit_constraint", [&] {
    auto& r = live(request, kRequestTag, "request").request;
    softshell::LimitConstraint c;
    c.point = point(p, "point");
    c.displacement = vec(displacement, "displacement");
    if (du_displacement) c.du_displacement = vec(du_displacement, "du_displacement");
    if (dv_displacement) c.dv_displacement = vec(dv_displacement, "dv_displacement");
    r.limit_constraints.push_back(c);
  });
}

ss_status ss_request_add_lagrange_constraint(ss_request* request, const int32_t* indices, const ss_vec3* coefficients,
                                             int32_t count, const ss_vec3* values) {
  return guard("ss_request_add_lagrange_constraint", [&] {
    auto& r = live(request, kRequestTag, "request").request;
    if (count_arg(count, "count") == 0) fail(ErrorCode::kInvalidArgument, "a Lagrange constraint needs control points");
    required(indices, "indices");
    required(coefficients, "coefficients");
    softshell::LagrangeConstraint c;
    for (int32_t k = 0; k < count; ++k) {
      if (indices[k] < 0) fail(ErrorCode::kInvalidArgument, "control point index must not be negative");
      c.indices.push_back(indices[k]);
      c.coefficients.push_back(vec(&coefficients[k], "coefficients"));
    }
    c.values = vec(values, "values");
    r.lagrange_constraints.push_back(std::move(c));
  });
}

ss_status ss_request_set_surface_load(ss_request* request, const ss_vec3* load_per_area) {
  return guard("ss_request_set_surface_load", [&] {
    live(request, kRequestTag, "request").request.surface_load = vec(load_per_area, "load_per_area");
  });
}

ss_status ss_request_set_pressure(ss_request* request, double pressure) {
  return guard("ss_request_set_pressure", [&] {
    auto& r = live(request, kRequestTag, "request").request;
    if (!std::isfinite(pressure)) fail(ErrorCode::kInvalidArgument, "pressure must be finite");
    r.pressure = pressure;
  });
}

ss_status ss_request_add_floor(ss_request* request, const ss_tessellation* tessellation, const ss_vec3* plane_point,
                               const ss_vec3* plane_normal, const ss_floor_options* options, int32_t* out_points,
                               int32_t* out_fixes_rigid_motion) {
  return guard("ss_request_add_floor", [&] {
    auto& r = live(request, kRequestTag, "request").request;
    const auto& t = *live(tessellation, kTessellationTag, "tessellation").tessellation;
    softshell::FloorOptions o;
    if (options) {
      o.tolerance = options->tolerance;
      o.axes = options->normal_only ? softshell::FloorAxes::kNormal : softshell::FloorAxes::kAll;
      o.snap = options->snap != 0;
    }
    const softshell::FloorContact contact =
        softshell::floor_contact(t, softshell::Plane{vec(plane_point, "plane_point"), vec(plane_normal, "plane_normal")}, o)
            .value();
    contact.add_to(r);
    if (out_points) *out_points = static_cast<int32_t>(contact.points.size());
    if (out_fixes_rigid_motion) *out_fixes_rigid_motion = contact.fixes_rigid_motion ? 1 : 0;
  });
}

ss_status ss_request_counts(const ss_request* request, int32_t* out_vertex_constraints,
                            int32_t* out_lagrange_constraints, int32_t* out_forces, int32_t* out_limit_constraints,
                            int32_t* out_surface_forces) {
  return guard("ss_request_counts", [&] {
    const auto& r = live(request, kRequestTag, "request").request;
    if (out_vertex_constraints) *out_vertex_constraints = static_cast<int32_t>(r.vertex_constraints.size());
    if (out_lagrange_constraints) *out_lagrange_constraints = static_cast<int32_t>(r.lagrange_constraints.size());
    if (out_forces) *out_forces = static_cast<int32_t>(r.forces.size());
    if (out_limit_constraints) *out_limit_constraints = static_cast<int32_t>(r.limit_constraints.size());
    if (out_surface_forces) *out_surface_forces = static_cast<int32_t>(r.surface_forces.size());
  });
}

ss_status ss_grab_begin(const ss_evaluator* evaluator, const ss_surface_point* p, const double* current_xyz,
                        int32_t count, const ss_pose* hand, const ss_grab_options* options, ss_grab** out_grab) {
  return guard("ss_grab_begin", [&] {
    required(out_grab, "out_grab");
    *out_grab = nullptr;
    const auto& ev = live(evaluator, kEvaluatorTag, "evaluator").evaluator;
    softshell::GrabOptions o;
    if (options) {
      o.follow_rotation = options->follow_rotation != 0;
      o.constrain_tangents = options->constrain_tangents != 0;
    }
    const std::vector<Vec3> current = (current_xyz == nullptr && count == 0)
                                          ? ev.mesh().positions()
                                          : read_xyz(current_xyz, count, "current_xyz");
    softshell::Grab g = softshell::Grab::begin(ev, point(p, "point"), current, pose(hand, "hand"), o).value();
    *out_grab = new ss_grab{kGrabTag, std::move(g)};
  });
}

void ss_grab_destroy(ss_grab* grab) { destroy(grab, kGrabTag); }

ss_status ss_grab_target(const ss_grab* grab, const ss_pose* hand, ss_vec3* out_target) {
  return guard("ss_grab_target", [&] {
    const auto& g = live(grab, kGrabTag, "grab").grab;
    required(out_target, "out_target");
    *out_target = to_c(g.target(pose(hand, "hand")));
  });
}

ss_status ss_request_add_grab(ss_request* request, const ss_grab* grab, const ss_pose* hand) {
  return guard("ss_request_add_grab", [&] {
    auto& r = live(request, kRequestTag, "request").request;
    const auto& g = live(grab, kGrabTag, "grab").grab;
    r.limit_constraints.push_back(g.constraint(pose(hand, "hand")));
  });
}

// ------------------------------------------------------------------------------------------------
// Levels of detail

ss_status ss_refinement_create(const ss_mesh* coarse, int32_t levels, ss_refinement** out_refinement) {
  return guard("ss_refinement_create", [&] {
    required(out_refinement, "out_refinement");
    *out_refinement = nullptr;
    const auto& m = live(coarse, kMeshTag, "coarse");
    *out_refinement = new ss_refinement{kRefinementTag, softshell::MeshRefinement::create(m.mesh, levels).value()};
  });
}

void ss_refinement_destroy(ss_refinement* refinement) { destroy(refinement, kRefinementTag); }

ss_status ss_refinement_fine_mesh(const ss_refinement* refinement, ss_mesh** out_mesh) {
  return guard("ss_refinement_fine_mesh", [&] {
    required(out_mesh, "out_mesh");
    *out_mesh = nullptr;
    const auto& r = live(refinement, kRefinementTag, "refinement").refinement;
    auto handle = std::make_unique<ss_mesh>();
    handle->mesh = r.fine();
    *out_mesh = handle.release();
  });
}

ss_status ss_refinement_fine_point(const ss_refinement* refinement, const ss_surface_point* coarse_point,
                                   ss_surface_point* out_fine_point) {
  return guard("ss_refinement_fine_point", [&] {
    const auto& r = live(refinement, kRefinementTag, "refinement").refinement;
    required(out_fine_point, "out_fine_point");
    *out_fine_point = to_c(r.fine_point(point(coarse_point, "coarse_point")).value());
  });
}

ss_status ss_refinement_refine_positions(const ss_refinement* refinement, const double* coarse_xyz, int32_t count,
                                         double* out_fine_xyz, int32_t capacity, int32_t* out_count) {
  return guard("ss_refinement_refine_positions", [&] {
    const auto& r = live(refinement, kRefinementTag, "refinement").refinement;
    const std::vector<Vec3> fine = r.refine_positions(read_xyz(coarse_xyz, count, "coarse_xyz")).value();
    write_xyz(fine, out_fine_xyz, capacity, out_count, "fine positions");
  });
}

ss_status ss_refinement_request_to_fine(const ss_refinement* refinement, const ss_request* coarse_request,
                                        int32_t force_transfer, ss_request** out_fine_request) {
  return guard("ss_refinement_request_to_fine", [&] {
    required(out_fine_request, "out_fine_request");
    *out_fine_request = nullptr;
    const auto& r = live(refinement, kRefinementTag, "refinement").refinement;
    const auto& req = live(coarse_request, kRequestTag, "coarse_request").request;
    if (force_transfer != SS_FORCE_TRANSFER_SUBDIVIDE && force_transfer != SS_FORCE_TRANSFER_VIRTUAL_WORK) {
      fail(ErrorCode::kInvalidArgument, "force_transfer must be SS_FORCE_TRANSFER_SUBDIVIDE or _VIRTUAL_WORK");
    }
    const auto transfer = force_transfer == SS_FORCE_TRANSFER_VIRTUAL_WORK ? softshell::ForceTransfer::kVirtualWork
                                                                           : softshell::ForceTransfer::kSubdivide;
    auto handle = std::make_unique<ss_request>();
    handle->request = r.request_to_fine(req, transfer).value();
    *out_fine_request = handle.release();
  });
}

// ------------------------------------------------------------------------------------------------
// Sessions

void ss_remote_options_default(ss_remote_options* out) {
  if (out) *out = ss_remote_options{0, 0, 0, 0};
}

ss_status ss_session_create_remote(const char* url, const ss_remote_options* options, ss_session** out_session) {
  return guard("ss_session_create_remote", [&] {
    required(out_session, "out_session");
    *out_session = nullptr;
    required(url, "url");
    ss_remote_options o;
    ss_remote_options_default(&o);
    if (options) o = *options;
    if (o.connect_timeout_ms < 0 || o.request_timeout_ms < 0 || o.async_threads < 0 || o.async_threads > 256) {
      fail(ErrorCode::kInvalidArgument, "remote options: timeouts must be >= 0 and async_threads in 0..256");
    }
    softshell::RemoteSessionOptions ro;
    ro.format = o.binary ? softshell::wire::Format::kBinary : softshell::wire::Format::kJson;
    if (o.connect_timeout_ms > 0) ro.connect_timeout = std::chrono::milliseconds(o.connect_timeout_ms);
    if (o.request_timeout_ms > 0) ro.request_timeout = std::chrono::milliseconds(o.request_timeout_ms);
    if (o.async_threads > 0) ro.async_threads = o.async_threads;
    std::shared_ptr<softshell::Session> session = softshell::RemoteSession::connect(url, ro).value();
    *out_session = softshell::c_api::wrap_session(std::move(session));
  });
}

void ss_session_destroy(ss_session* session) { destroy(session, kSessionTag); }

ss_status ss_geom_id_to_hex(const ss_geom_id* id, char* out, int32_t capacity) {
  return guard("ss_geom_id_to_hex", [&] {
    required(id, "id");
    required(out, "out");
    if (capacity < 33) throw CStatus{SS_BUFFER_TOO_SMALL, "needs 33 characters (32 hex digits and NUL)"};
    static constexpr char kHex[] = "0123456789abcdef";
    for (int i = 0; i < 16; ++i) {
      out[2 * i] = kHex[id->bytes[i] >> 4];
      out[2 * i + 1] = kHex[id->bytes[i] & 15];
    }
    out[32] = '\0';
  });
}

ss_status ss_session_upload(ss_session* session, const ss_mesh* mesh, const ss_material* material,
                            const char* name_space, ss_geom_id* out_id, int32_t* out_created) {
  return guard("ss_session_upload", [&] {
    auto& s = live(session, kSessionTag, "session");
    const auto& m = live(mesh, kMeshTag, "mesh");
    required(material, "material");
    required(out_id, "out_id");
    softshell::Material mat;
    mat.youngs_modulus = material->youngs_modulus;
    mat.poisson_ratio = material->poisson_ratio;
    mat.thickness = material->thickness;
    mat.density = material->density;
    const softshell::UploadResult r = s.session->upload(m.mesh, mat, name_space ? name_space : "").value();
    std::memcpy(out_id->bytes, r.id.bytes.data(), 16);
    if (out_created) *out_created = r.created ? 1 : 0;
  });
}

ss_status ss_session_deform(ss_session* session, const ss_geom_id* id, const ss_request* request,
                            uint32_t* out_res_id, double* out_xyz, int32_t capacity, int32_t* out_count) {
  return guard("ss_session_deform", [&] {
    auto& s = live(session, kSessionTag, "session");
    const auto& req = live(request, kRequestTag, "request").request;
    required(out_res_id, "out_res_id");
    required(out_count, "out_count");
    const softshell::DeformationResult r = s.session->deform(geom_id(id), req).value();
    write_xyz(r.positions, out_xyz, capacity, out_count, "deformed positions");
    *out_res_id = r.res_id;
  });
}

ss_status ss_session_deform_begin(ss_session* session, const ss_geom_id* id, const ss_request* request,
                                  ss_deformation** out_operation) {
  return guard("ss_session_deform_begin", [&] {
    required(out_operation, "out_operation");
    *out_operation = nullptr;
    auto& s = live(session, kSessionTag, "session");
    const auto& req = live(request, kRequestTag, "request").request;
    reaper().purge_finished();
    auto op = std::make_unique<ss_deformation>();
    op->session = s.session;
    op->future = s.session->deform_async(geom_id(id), req).share();
    if (!op->future.valid()) fail(ErrorCode::kInternal, "the session returned no future");
    *out_operation = op.release();
  });
}

ss_status ss_deformation_poll(ss_deformation* operation, int32_t* out_ready) {
  return guard("ss_deformation_poll", [&] {
    const auto& op = live(operation, kDeformationTag, "operation");
    required(out_ready, "out_ready");
    *out_ready = ready(op) ? 1 : 0;
  });
}

ss_status ss_deformation_wait(ss_deformation* operation, int32_t timeout_ms, int32_t* out_ready) {
  return guard("ss_deformation_wait", [&] {
    const auto& op = live(operation, kDeformationTag, "operation");
    required(out_ready, "out_ready");
    count_arg(timeout_ms, "timeout_ms");
    *out_ready = op.future.wait_for(std::chrono::milliseconds(timeout_ms)) == std::future_status::ready ? 1 : 0;
  });
}

ss_status ss_deformation_read(ss_deformation* operation, uint32_t* out_res_id, double* out_xyz, int32_t capacity,
                              int32_t* out_count) {
  return guard("ss_deformation_read", [&] {
    const auto& op = live(operation, kDeformationTag, "operation");
    required(out_res_id, "out_res_id");
    required(out_count, "out_count");
    if (!ready(op)) throw CStatus{SS_NOT_READY, "the deformation is still running; poll until it is ready"};
    const softshell::Result<softshell::DeformationResult>& r = op.future.get();
    if (!r.ok()) throw softshell::Exception(r.error());
    write_xyz(r.value().positions, out_xyz, capacity, out_count, "deformed positions");
    *out_res_id = r.value().res_id;
  });
}

void ss_deformation_destroy(ss_deformation* operation) {
  if (operation == nullptr || operation->tag != kDeformationTag) return;
  try {
    if (operation->future.valid() && !ready(*operation)) reaper().adopt(operation->session, operation->future);
  } catch (...) {
    // Out of memory while adopting: fall through; the destructor below may then wait.
  }
  destroy(operation, kDeformationTag);
}

ss_status ss_session_latest_result(ss_session* session, const ss_geom_id* id, uint32_t have, int32_t wait_ms,
                                   int32_t* out_has_new, uint32_t* out_res_id, double* out_xyz, int32_t capacity,
                                   int32_t* out_count) {
  return guard("ss_session_latest_result", [&] {
    auto& s = live(session, kSessionTag, "session");
    required(out_has_new, "out_has_new");
    required(out_res_id, "out_res_id");
    required(out_count, "out_count");
    count_arg(wait_ms, "wait_ms");
    *out_has_new = 0;
    const auto r = s.session->latest_result(geom_id(id), have, std::chrono::milliseconds(wait_ms)).value();
    if (!r) {
      *out_count = 0;
      return;
    }
    write_xyz(r->positions, out_xyz, capacity, out_count, "deformed positions");
    *out_res_id = r->res_id;
    *out_has_new = 1;
  });
}

}  // extern "C"
